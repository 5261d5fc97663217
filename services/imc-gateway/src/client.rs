//! The peer side of IMC over UDP: what Neptus or DUNE does, for the tests and the
//! `skymesh-imc` command-line client. Datagrams are written little-endian with the
//! same codec as the gateway's and everything that arrives is decoded with it.

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use imc_proto::{
    decode_datagram, encode_datagram, DecodeError, EncodeError, Header, Message, Packet,
};
use tokio::net::UdpSocket;
use tokio::time::Instant;

/// Why the client could not do what was asked.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("cannot encode the message: {0}")]
    Encode(#[from] EncodeError),
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

/// The header fields the client writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Identity {
    /// Our IMC address (`src`).
    pub src: u16,
    pub src_ent: u8,
    /// The gateway's address (`dst`); 0xFFFF reaches any system.
    pub dst: u16,
    pub dst_ent: u8,
}

impl Default for Identity {
    /// A CCU-like address (0x4001, as a Neptus console) to any system.
    fn default() -> Self {
        Identity {
            src: 0x4001,
            src_ent: 0,
            dst: imc_proto::ADDR_NONE,
            dst_ent: imc_proto::ENTITY_ANY,
        }
    }
}

/// One datagram that arrived: where from, and what it decoded to.
#[derive(Debug, Clone, PartialEq)]
pub struct Received {
    pub from: SocketAddr,
    pub packet: Result<Packet, DecodeError>,
}

/// A UDP socket that talks IMC to one gateway (and hears from anyone).
#[derive(Debug)]
pub struct ImcClient {
    socket: UdpSocket,
    target: SocketAddr,
    pub identity: Identity,
}

fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

impl ImcClient {
    /// A client on a free port of the loopback (for a loopback target) or any
    /// address of the target's family.
    pub async fn connect(target: SocketAddr) -> std::io::Result<ImcClient> {
        let local: IpAddr = match target.ip() {
            IpAddr::V4(ip) if ip.is_loopback() => Ipv4Addr::LOCALHOST.into(),
            IpAddr::V4(_) => Ipv4Addr::UNSPECIFIED.into(),
            IpAddr::V6(ip) if ip.is_loopback() => Ipv6Addr::LOCALHOST.into(),
            IpAddr::V6(_) => Ipv6Addr::UNSPECIFIED.into(),
        };
        ImcClient::bind(SocketAddr::new(local, 0), target).await
    }

    /// A client on `local` (port 0 for any).
    pub async fn bind(local: SocketAddr, target: SocketAddr) -> std::io::Result<ImcClient> {
        Ok(ImcClient {
            socket: UdpSocket::bind(local).await?,
            target,
            identity: Identity::default(),
        })
    }

    pub fn local_addr(&self) -> std::io::Result<SocketAddr> {
        self.socket.local_addr()
    }

    pub fn target(&self) -> SocketAddr {
        self.target
    }

    /// The datagram `send` would write.
    pub fn datagram(&self, message: &Message) -> Result<Vec<u8>, EncodeError> {
        let id = self.identity;
        let header = Header {
            mgid: 0,
            size: 0,
            timestamp: unix_now(),
            src: id.src,
            src_ent: id.src_ent,
            dst: id.dst,
            dst_ent: id.dst_ent,
        };
        encode_datagram(&header, message)
    }

    /// Sends one message to the target.
    pub async fn send(&self, message: &Message) -> Result<(), ClientError> {
        let bytes = self.datagram(message)?;
        self.send_raw(&bytes).await?;
        Ok(())
    }

    /// Sends bytes as they are (broken datagrams for the tests).
    pub async fn send_raw(&self, bytes: &[u8]) -> std::io::Result<()> {
        self.socket.send_to(bytes, self.target).await?;
        Ok(())
    }

    /// The next datagram within `timeout`, decoded or not; `Ok(None)` on timeout.
    pub async fn recv_datagram(&self, timeout: Duration) -> std::io::Result<Option<Received>> {
        let mut buf = vec![0u8; 65_536];
        match tokio::time::timeout(timeout, self.socket.recv_from(&mut buf)).await {
            Err(_) => Ok(None),
            Ok(Err(e)) => Err(e),
            Ok(Ok((n, from))) => Ok(Some(Received {
                from,
                packet: decode_datagram(&buf[..n]),
            })),
        }
    }

    /// The first packet within `timeout` for which `pred` holds; others (and
    /// datagrams that do not decode) are discarded.
    pub async fn recv_until(
        &self,
        timeout: Duration,
        mut pred: impl FnMut(&Packet) -> bool,
    ) -> Option<Packet> {
        let deadline = Instant::now() + timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.recv_datagram(left).await {
                Ok(Some(Received { packet: Ok(p), .. })) if pred(&p) => return Some(p),
                Ok(Some(_)) => {}
                // A receive error (e.g. ICMP port unreachable) is not an answer.
                Err(_) if !left.is_zero() => {}
                Ok(None) | Err(_) => return None,
            }
        }
    }

    /// The first message within `timeout` for which `pred` holds.
    pub async fn recv_message(
        &self,
        timeout: Duration,
        mut pred: impl FnMut(&Message) -> bool,
    ) -> Option<Message> {
        self.recv_until(timeout, |p| pred(&p.message))
            .await
            .map(|p| p.message)
    }

    /// Sends `message` and waits up to `timeout` for a message matching `pred`.
    pub async fn request(
        &self,
        message: &Message,
        timeout: Duration,
        pred: impl FnMut(&Message) -> bool,
    ) -> Result<Option<Message>, ClientError> {
        self.send(message).await?;
        Ok(self.recv_message(timeout, pred).await)
    }

    /// Waits `period` and returns every message that arrived that is not a
    /// Heartbeat or Announce (to check that nothing was answered).
    pub async fn replies_within(&self, period: Duration) -> Vec<Message> {
        let deadline = Instant::now() + period;
        let mut out = Vec::new();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return out;
            }
            if let Ok(Some(Received { packet: Ok(p), .. })) = self.recv_datagram(left).await {
                if !matches!(p.message, Message::Heartbeat | Message::Announce(_)) {
                    out.push(p.message);
                }
            }
        }
    }
}
