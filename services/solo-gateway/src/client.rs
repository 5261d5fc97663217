//! The app side of the protocol: what a Solo phone app does, for the end-to-end
//! tests and the `skymesh-solo` command-line client.
//!
//! [`AppClient`] holds the TCP connection (port 5507) and decodes what arrives with
//! the same codec as the gateway; [`FollowStreamer`] sends LOCATION datagrams to
//! the follow stream (port 14558).

use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

use solo_proto::{DecodeError, Location, RawFrame, SoloMessage, TlvCodec};
use tokio::io::AsyncWriteExt;
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::{TcpStream, UdpSocket};
use tokio::time::Instant;

use crate::framing::{FrameReader, ReadError};

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

/// One app connection to the gateway (or to any ShotManager).
#[derive(Debug)]
pub struct AppClient {
    reader: FrameReader<OwnedReadHalf>,
    writer: OwnedWriteHalf,
    local: SocketAddr,
    peer: SocketAddr,
    /// Why the connection ended, once it has.
    closed: Option<String>,
}

impl AppClient {
    /// Connects to `addr`.
    pub async fn connect(addr: SocketAddr) -> Result<AppClient, ClientError> {
        Self::connect_with(addr, None).await
    }

    /// Connects to `addr` from the local address `from` (port chosen by the system):
    /// e.g. `127.0.0.2` to look like a second phone on loopback.
    pub async fn connect_from(from: IpAddr, addr: SocketAddr) -> Result<AppClient, ClientError> {
        Self::connect_with(addr, Some(from)).await
    }

    async fn connect_with(
        addr: SocketAddr,
        from: Option<IpAddr>,
    ) -> Result<AppClient, ClientError> {
        let stream = skymesh_runtime::net::connect_tcp(addr, from)
            .await
            .map_err(|source| ClientError::Connect { addr, source })?;
        AppClient::from_stream(stream)
    }

    pub fn from_stream(stream: TcpStream) -> Result<AppClient, ClientError> {
        stream.set_nodelay(true)?;
        let local = stream.local_addr()?;
        let peer = stream.peer_addr()?;
        let (read, writer) = stream.into_split();
        Ok(AppClient {
            reader: FrameReader::new(read, TlvCodec::new(), None),
            writer,
            local,
            peer,
            closed: None,
        })
    }

    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    pub fn peer_addr(&self) -> SocketAddr {
        self.peer
    }

    /// Sends one message (header + value).
    pub async fn send(&mut self, msg: &SoloMessage) -> Result<(), ClientError> {
        self.send_raw(&msg.to_bytes()).await
    }

    /// Sends bytes as they are: partial frames, several frames, garbage.
    pub async fn send_raw(&mut self, bytes: &[u8]) -> Result<(), ClientError> {
        self.writer.write_all(bytes).await?;
        Ok(())
    }

    /// The next frame within `timeout`, decoded or not. `Ok(None)` on timeout;
    /// `Err(Closed)` once the connection has ended ([`AppClient::closed_reason`] says why).
    pub async fn recv_frame(
        &mut self,
        timeout: Duration,
    ) -> Result<Option<(RawFrame, Result<SoloMessage, DecodeError>)>, ClientError> {
        if self.closed.is_some() {
            return Err(ClientError::Closed);
        }
        match tokio::time::timeout(timeout, self.reader.next_frame()).await {
            Err(_) => Ok(None),
            Ok(Ok(Some(frame))) => {
                let decoded = SoloMessage::decode(frame.msg_type, &frame.value);
                Ok(Some((frame, decoded)))
            }
            Ok(Ok(None)) => {
                self.closed = Some("closed by the server".to_string());
                Err(ClientError::Closed)
            }
            Ok(Err(e)) => {
                self.closed = Some(match e {
                    ReadError::Frame(solo_proto::FrameError::Io(e)) => e.to_string(),
                    other => other.to_string(),
                });
                Err(ClientError::Closed)
            }
        }
    }

    /// The next message that decodes, within `timeout`; `None` on timeout or when the
    /// connection has closed (see [`AppClient::is_closed`]). Frames that do not
    /// decode are skipped.
    pub async fn recv(&mut self, timeout: Duration) -> Option<SoloMessage> {
        self.recv_until(timeout, |_| true).await
    }

    /// The first message within `timeout` for which `pred` holds; the others are
    /// discarded.
    pub async fn recv_until(
        &mut self,
        timeout: Duration,
        mut pred: impl FnMut(&SoloMessage) -> bool,
    ) -> Option<SoloMessage> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.recv_frame(left).await {
                Ok(Some((_, Ok(m)))) if pred(&m) => return Some(m),
                Ok(Some(_)) => {}
                Ok(None) | Err(_) => return None,
            }
        }
    }

    /// Waits up to `timeout` for the server to close the connection, discarding what
    /// arrives meanwhile. True if it closed.
    pub async fn wait_closed(&mut self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.recv_frame(left).await {
                Err(_) => return true,
                Ok(None) => return false,
                Ok(Some(_)) => {}
            }
        }
    }

    /// True once a receive has seen the connection end.
    pub fn is_closed(&self) -> bool {
        self.closed.is_some()
    }

    pub fn closed_reason(&self) -> Option<&str> {
        self.closed.as_deref()
    }
}

/// Sends the app's position to the follow stream, one LOCATION datagram each.
#[derive(Debug)]
pub struct FollowStreamer {
    socket: UdpSocket,
    target: SocketAddr,
}

impl FollowStreamer {
    /// A sender from any local port, of the address family of `target`.
    pub async fn new(target: SocketAddr) -> std::io::Result<FollowStreamer> {
        let any: IpAddr = if target.is_ipv4() {
            [0, 0, 0, 0].into()
        } else {
            std::net::Ipv6Addr::UNSPECIFIED.into()
        };
        FollowStreamer::bind(any, target).await
    }

    /// A sender from the local address `from` (the follow stream accepts only the
    /// connected app's address).
    pub async fn bind(from: IpAddr, target: SocketAddr) -> std::io::Result<FollowStreamer> {
        let socket = UdpSocket::bind(SocketAddr::new(from, 0)).await?;
        Ok(FollowStreamer { socket, target })
    }

    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    /// Sends one LOCATION datagram.
    pub async fn send(&self, location: Location) -> std::io::Result<()> {
        self.send_raw(&SoloMessage::Location(location).to_bytes())
            .await
    }

    /// Sends one datagram as it is.
    pub async fn send_raw(&self, datagram: &[u8]) -> std::io::Result<()> {
        self.socket.send_to(datagram, self.target).await?;
        Ok(())
    }
}
