//! The client side of the interface: what a GroundControl application does, for
//! the tests and the `skymesh-gc` command-line tool.
//!
//! [`GcClient`] holds a state-server connection (TCP 8000) and reads records with
//! the same codec as the gateway; [`PoseListener`] receives the pose broadcast
//! (UDP 6666).

use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

use bytes::BytesMut;
use gc_proto::{decode_pose_datagram, PoseDatagramError, PoseRecord, Record, RecordCodec};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::{TcpStream, UdpSocket};
use tokio::time::Instant;
use tokio_util::codec::Decoder;

/// Why the client could not do what was asked.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("cannot connect to {addr}: {source}")]
    Connect {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error("the connection is closed")]
    Closed,
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// One state-server connection.
#[derive(Debug)]
pub struct GcClient {
    read: OwnedReadHalf,
    write: OwnedWriteHalf,
    buf: BytesMut,
    local: SocketAddr,
    peer: SocketAddr,
    closed: bool,
}

impl GcClient {
    /// Connects to `addr`.
    pub async fn connect(addr: SocketAddr) -> Result<GcClient, ClientError> {
        Self::connect_with(addr, None).await
    }

    /// Connects to `addr` from the local address `from` (port chosen by the system):
    /// e.g. `127.0.0.2`: a client that is not on a privileged list of `127.0.0.1`.
    pub async fn connect_from(from: IpAddr, addr: SocketAddr) -> Result<GcClient, ClientError> {
        Self::connect_with(addr, Some(from)).await
    }

    async fn connect_with(addr: SocketAddr, from: Option<IpAddr>) -> Result<GcClient, ClientError> {
        let stream = skymesh_runtime::net::connect_tcp(addr, from)
            .await
            .map_err(|source| ClientError::Connect { addr, source })?;
        GcClient::from_stream(stream)
    }

    pub fn from_stream(stream: TcpStream) -> Result<GcClient, ClientError> {
        stream.set_nodelay(true)?;
        let local = stream.local_addr()?;
        let peer = stream.peer_addr()?;
        let (read, write) = stream.into_split();
        Ok(GcClient {
            read,
            write,
            buf: BytesMut::with_capacity(4096),
            local,
            peer,
            closed: false,
        })
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    pub fn peer_addr(&self) -> SocketAddr {
        self.peer
    }

    /// Sends one record.
    pub async fn send(&mut self, record: &Record) -> Result<(), ClientError> {
        self.send_raw(&record.encode()).await
    }

    /// Sends several records in one write.
    pub async fn send_all(&mut self, records: &[Record]) -> Result<(), ClientError> {
        let bytes: Vec<u8> = records.iter().flat_map(|r| r.encode()).collect();
        self.send_raw(&bytes).await
    }

    /// Sends bytes as they are: partial records, garbage.
    pub async fn send_raw(&mut self, bytes: &[u8]) -> Result<(), ClientError> {
        self.write.write_all(bytes).await?;
        Ok(())
    }

    /// Closes the sending half (the server sees end of stream).
    pub async fn shutdown_write(&mut self) -> Result<(), ClientError> {
        self.write.shutdown().await?;
        Ok(())
    }

    /// The next record within `timeout`: `Ok(None)` on timeout, `Err(Closed)` once
    /// the server has closed the connection.
    pub async fn recv(&mut self, timeout: Duration) -> Result<Option<Record>, ClientError> {
        let deadline = Instant::now() + timeout;
        loop {
            let mut codec = RecordCodec::new();
            if let Ok(Some(r)) = codec.decode(&mut self.buf) {
                return Ok(Some(r));
            }
            if self.closed {
                return Err(ClientError::Closed);
            }
            self.buf.reserve(4096);
            match tokio::time::timeout_at(deadline, self.read.read_buf(&mut self.buf)).await {
                Err(_) => return Ok(None),
                Ok(Ok(0)) => self.closed = true,
                Ok(Ok(_)) => {}
                Ok(Err(_)) => self.closed = true,
            }
        }
    }

    /// The first record within `timeout` for which `pred` holds; the others are
    /// discarded. `None` on timeout or close.
    pub async fn recv_until(
        &mut self,
        timeout: Duration,
        mut pred: impl FnMut(&Record) -> bool,
    ) -> Option<Record> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.recv(left).await {
                Ok(Some(r)) if pred(&r) => return Some(r),
                Ok(Some(_)) => {}
                Ok(None) | Err(_) => return None,
            }
        }
    }

    /// Every record that arrives within `window`.
    pub async fn collect_for(&mut self, window: Duration) -> Vec<Record> {
        let deadline = Instant::now() + window;
        let mut out = Vec::new();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.recv(left).await {
                Ok(Some(r)) => out.push(r),
                Ok(None) | Err(_) => return out,
            }
        }
    }

    /// Waits up to `timeout` for the server to close the connection, discarding what
    /// arrives meanwhile. True if it closed.
    pub async fn wait_closed(&mut self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.recv(left).await {
                Err(_) => return true,
                Ok(None) => return false,
                Ok(Some(_)) => {}
            }
        }
    }

    /// True once a receive has seen the connection end.
    pub fn is_closed(&self) -> bool {
        self.closed
    }
}

/// Receives the pose broadcast.
#[derive(Debug)]
pub struct PoseListener {
    socket: UdpSocket,
    buf: Vec<u8>,
}

impl PoseListener {
    /// Listens on `addr` (`0.0.0.0:6666` receives subnet broadcasts too).
    pub async fn bind(addr: SocketAddr) -> std::io::Result<PoseListener> {
        Ok(PoseListener {
            socket: UdpSocket::bind(addr).await?,
            buf: vec![0; 65_536],
        })
    }

    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// The next datagram within `timeout` (`None` on timeout), decoded.
    pub async fn recv(
        &mut self,
        timeout: Duration,
    ) -> std::io::Result<Option<(SocketAddr, Result<Vec<PoseRecord>, PoseDatagramError>)>> {
        match tokio::time::timeout(timeout, self.socket.recv_from(&mut self.buf)).await {
            Err(_) => Ok(None),
            Ok(Err(e)) => Err(e),
            Ok(Ok((n, from))) => Ok(Some((from, decode_pose_datagram(&self.buf[..n])))),
        }
    }
}
