//! The autopilot's byte transports: TCP, UDP and serial, each split into a reading
//! and a writing half. The writing half is used by the link's writer thread
//! (blocking) and, for a socket, by the sending task through a non-blocking second
//! handle ([`DirectWriter`]); a socket's reading half is waited on in tokio's reactor
//! ([`SocketReader`]: one wake-up per arriving datagram, on the thread that then
//! handles it), a serial port's by the link's reader thread (blocking).
//!
//! Raw bytes rather than the `mavlink` crate's connections, because the router
//! forwards frames byte for byte, including message ids the crate's dialect does
//! not know (its reader drops those). Every read returns within [`POLL`] so the
//! threads see their stop flag.

use std::io::{self, IoSliceMut, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream, ToSocketAddrs, UdpSocket};
use std::os::fd::{AsRawFd, RawFd};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use crate::config::Endpoint;

/// How often blocking reads, writes and accepts look at the stop flag.
pub const POLL: Duration = Duration::from_millis(100);
/// How long a TCP connect may take (a host that drops SYNs would block for minutes).
const CONNECT_TIMEOUT: Duration = Duration::from_secs(3);
/// A write blocked this long (peer stopped reading) fails the connection.
const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

/// Where UDP replies go: fixed for `udpout`, the last sender for `udpin`.
type Destination = Arc<Mutex<Option<SocketAddr>>>;

fn lock(d: &Destination) -> std::sync::MutexGuard<'_, Option<SocketAddr>> {
    d.lock().unwrap_or_else(PoisonError::into_inner)
}

/// The reading half.
#[derive(Debug)]
pub enum Reader {
    Tcp(TcpStream),
    Udp {
        socket: UdpSocket,
        /// `udpin`: remember who spoke last, replies go there.
        reply_to: Option<Destination>,
    },
    Serial(Box<dyn serialport::SerialPort>),
}

/// What one read produced.
#[derive(Debug, PartialEq, Eq)]
pub enum Received {
    /// `n` bytes of a stream.
    Stream(usize),
    /// One datagram of `n` bytes (frames never span datagrams).
    Datagram(usize),
    /// Nothing within [`POLL`].
    Idle,
    /// The other end closed the stream.
    Closed,
}

fn is_idle(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
    )
}

impl Reader {
    pub fn read(&mut self, buf: &mut [u8]) -> io::Result<Received> {
        let r = match self {
            Reader::Tcp(s) => s.read(buf).map(|n| match n {
                0 => Received::Closed,
                n => Received::Stream(n),
            }),
            Reader::Udp { socket, reply_to } => socket.recv_from(buf).map(|(n, from)| {
                if let Some(dest) = reply_to {
                    *lock(dest) = Some(from);
                }
                Received::Datagram(n)
            }),
            Reader::Serial(p) => p.read(buf).map(|n| match n {
                // poll() said readable and nothing came: the device went away.
                0 => Received::Closed,
                n => Received::Stream(n),
            }),
        };
        match r {
            Err(e) if is_idle(&e) => Ok(Received::Idle),
            // ICMP port unreachable from a peer that is not listening (yet): not fatal.
            Err(e) if e.kind() == io::ErrorKind::ConnectionRefused && self.is_udp() => {
                Ok(Received::Idle)
            }
            r => r,
        }
    }

    fn is_udp(&self) -> bool {
        matches!(self, Reader::Udp { .. })
    }

    /// The socket transports, to be read from tokio's reactor; a serial port (read
    /// by a blocking thread) is handed back.
    pub fn into_socket(self) -> Result<SocketReader, Reader> {
        match self {
            Reader::Tcp(s) => Ok(SocketReader::Tcp(s)),
            Reader::Udp { socket, reply_to } => Ok(SocketReader::Udp { socket, reply_to }),
            serial @ Reader::Serial(_) => Err(serial),
        }
    }
}

/// A socket's reading half, read without blocking (`MSG_DONTWAIT`) when tokio's
/// reactor says it is readable. The socket itself stays in blocking mode: the
/// file description is shared with the writer thread's half, whose blocking
/// writes (with their timeout) must not start failing with `WouldBlock`.
#[derive(Debug)]
pub enum SocketReader {
    Tcp(TcpStream),
    Udp {
        socket: UdpSocket,
        /// `udpin`: remember who spoke last, replies go there.
        reply_to: Option<Destination>,
    },
}

impl AsRawFd for SocketReader {
    fn as_raw_fd(&self) -> RawFd {
        match self {
            SocketReader::Tcp(s) => s.as_raw_fd(),
            SocketReader::Udp { socket, .. } => socket.as_raw_fd(),
        }
    }
}

impl SocketReader {
    /// Reads what has arrived without waiting: one datagram, or what the stream
    /// holds up to `buf`'s size; [`Received::Idle`] when nothing has.
    pub fn read_now(&mut self, buf: &mut [u8]) -> io::Result<Received> {
        use nix::errno::Errno;
        use nix::sys::socket::{self, MsgFlags, SockaddrStorage};
        let fd = self.as_raw_fd();
        loop {
            let r = match self {
                SocketReader::Tcp(_) => socket::recv(fd, buf, MsgFlags::MSG_DONTWAIT).map(|n| {
                    if n == 0 {
                        Received::Closed
                    } else {
                        Received::Stream(n)
                    }
                }),
                SocketReader::Udp { reply_to, .. } => {
                    let mut iov = [IoSliceMut::new(buf)];
                    socket::recvmsg::<SockaddrStorage>(fd, &mut iov, None, MsgFlags::MSG_DONTWAIT)
                        .map(|m| {
                            if let (Some(dest), Some(from)) =
                                (reply_to, m.address.as_ref().and_then(std_addr))
                            {
                                *lock(dest) = Some(from);
                            }
                            Received::Datagram(m.bytes)
                        })
                }
            };
            return match r {
                Ok(received) => Ok(received),
                Err(Errno::EAGAIN) => Ok(Received::Idle),
                Err(Errno::EINTR) => continue,
                // ICMP port unreachable from a peer that is not listening (yet): not
                // fatal, and a datagram may be queued behind it.
                Err(Errno::ECONNREFUSED) if matches!(self, SocketReader::Udp { .. }) => continue,
                Err(e) => Err(io::Error::from(e)),
            };
        }
    }
}

fn std_addr(a: &nix::sys::socket::SockaddrStorage) -> Option<SocketAddr> {
    if let Some(v4) = a.as_sockaddr_in() {
        return Some(SocketAddr::V4((*v4).into()));
    }
    a.as_sockaddr_in6().map(|v6| SocketAddr::V6((*v6).into()))
}

/// The writing half.
#[derive(Debug)]
pub enum Writer {
    Tcp(TcpStream),
    Udp {
        socket: UdpSocket,
        destination: Destination,
    },
    Serial(Box<dyn serialport::SerialPort>),
}

impl Writer {
    /// Writes one whole frame. UDP with nobody to reply to yet (`udpin` before the
    /// autopilot spoke) drops it, as the `mavlink` crate does.
    pub fn write_frame(&mut self, frame: &[u8]) -> io::Result<()> {
        match self {
            Writer::Tcp(s) => s.write_all(frame),
            Writer::Serial(p) => p.write_all(frame),
            Writer::Udp {
                socket,
                destination,
            } => {
                let Some(to) = *lock(destination) else {
                    return Ok(());
                };
                match socket.send_to(frame, to) {
                    Ok(_) => Ok(()),
                    // The autopilot's port is closed for now; UDP does not care.
                    Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => Ok(()),
                    Err(e) => Err(e),
                }
            }
        }
    }
}

impl Writer {
    /// A second, non-blocking handle on a socket's writing half, for writes made
    /// straight from the task that produced the message ([`DirectWriter`]); `None`
    /// for a serial port (its writes take milliseconds at telemetry baud rates and
    /// stay on the writer thread).
    pub fn direct(&self) -> io::Result<Option<DirectWriter>> {
        Ok(match self {
            Writer::Tcp(s) => Some(DirectWriter::Tcp(s.try_clone()?)),
            Writer::Udp {
                socket,
                destination,
            } => Some(DirectWriter::Udp {
                socket: socket.try_clone()?,
                destination: destination.clone(),
            }),
            Writer::Serial(_) => None,
        })
    }
}

/// A socket's writing half that never waits: each write sends what the socket
/// takes now (`MSG_DONTWAIT`) and says how much that was.
#[derive(Debug)]
pub enum DirectWriter {
    Tcp(TcpStream),
    Udp {
        socket: UdpSocket,
        destination: Destination,
    },
}

impl DirectWriter {
    /// Sends `frame` without waiting: the bytes taken (a stream may take part of
    /// it), or `WouldBlock` if the socket takes none now. A datagram with no
    /// destination yet, or refused by the peer, counts as sent, as on the writer
    /// thread ([`Writer::write_frame`]).
    pub fn try_write(&self, frame: &[u8]) -> io::Result<usize> {
        use nix::errno::Errno;
        use nix::sys::socket::{self, MsgFlags, SockaddrStorage};
        let flags = MsgFlags::MSG_DONTWAIT | MsgFlags::MSG_NOSIGNAL;
        loop {
            let r = match self {
                DirectWriter::Tcp(s) => socket::send(s.as_raw_fd(), frame, flags),
                DirectWriter::Udp {
                    socket,
                    destination,
                } => {
                    let Some(to) = *lock(destination) else {
                        return Ok(frame.len());
                    };
                    let to = SockaddrStorage::from(to);
                    match socket::sendto(socket.as_raw_fd(), frame, &to, flags) {
                        Err(Errno::ECONNREFUSED) => return Ok(frame.len()),
                        r => r,
                    }
                }
            };
            return match r {
                Ok(n) => Ok(n),
                Err(Errno::EINTR) => continue,
                Err(e) => Err(io::Error::from(e)),
            };
        }
    }
}

/// Opens the transport (blocking). For `tcpin` the listener is kept across
/// connections and handed back.
pub fn open(
    endpoint: &Endpoint,
    listener: Option<Arc<TcpListener>>,
    stop: &AtomicBool,
) -> (Option<Arc<TcpListener>>, io::Result<(Reader, Writer)>) {
    match endpoint {
        Endpoint::TcpIn(addr) => {
            let listener = match listener {
                Some(l) => l,
                None => match TcpListener::bind(addr).and_then(|l| {
                    l.set_nonblocking(true)?;
                    Ok(l)
                }) {
                    Ok(l) => {
                        tracing::info!(%addr, "waiting for the autopilot to connect over TCP");
                        Arc::new(l)
                    }
                    Err(e) => return (None, Err(e)),
                },
            };
            let halves = accept(&listener, stop).and_then(stream);
            (Some(listener), halves)
        }
        Endpoint::TcpOut { host, port } => {
            let halves = resolve(host, *port)
                .and_then(|addr| TcpStream::connect_timeout(&addr, CONNECT_TIMEOUT))
                .and_then(stream);
            (None, halves)
        }
        Endpoint::UdpIn(addr) => (None, udp(*addr, None)),
        Endpoint::UdpOut { host, port } => {
            let halves = resolve(host, *port).and_then(|to| {
                let any: SocketAddr = if to.is_ipv4() {
                    ([0, 0, 0, 0], 0).into()
                } else {
                    (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
                };
                udp(any, Some(to))
            });
            (None, halves)
        }
        Endpoint::Serial { device, baud } => (None, serial(device, *baud)),
    }
}

fn resolve(host: &str, port: u16) -> io::Result<SocketAddr> {
    (host, port)
        .to_socket_addrs()?
        .next()
        .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, format!("{host} has no address")))
}

fn accept(listener: &TcpListener, stop: &AtomicBool) -> io::Result<TcpStream> {
    loop {
        match listener.accept() {
            Ok((stream, peer)) => {
                tracing::info!(%peer, "autopilot connected over TCP");
                stream.set_nonblocking(false)?;
                return Ok(stream);
            }
            Err(e) if is_idle(&e) => {
                if stop.load(Ordering::Relaxed) {
                    return Err(io::Error::new(io::ErrorKind::Interrupted, "stopped"));
                }
                std::thread::sleep(POLL);
            }
            Err(e) => return Err(e),
        }
    }
}

fn stream(stream: TcpStream) -> io::Result<(Reader, Writer)> {
    stream.set_read_timeout(Some(POLL))?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    stream.set_nodelay(true)?;
    let writer = stream.try_clone()?;
    Ok((Reader::Tcp(stream), Writer::Tcp(writer)))
}

/// `to` = None: `udpin` (reply to the last sender); Some: `udpout`.
fn udp(bind: SocketAddr, to: Option<SocketAddr>) -> io::Result<(Reader, Writer)> {
    let socket = UdpSocket::bind(bind)?;
    socket.set_read_timeout(Some(POLL))?;
    let destination: Destination = Arc::new(Mutex::new(to));
    let reader = Reader::Udp {
        socket: socket.try_clone()?,
        reply_to: to.is_none().then(|| destination.clone()),
    };
    Ok((
        reader,
        Writer::Udp {
            socket,
            destination,
        },
    ))
}

fn serial(device: &str, baud: u32) -> io::Result<(Reader, Writer)> {
    let port = serialport::new(device, baud)
        .data_bits(serialport::DataBits::Eight)
        .parity(serialport::Parity::None)
        .stop_bits(serialport::StopBits::One)
        .flow_control(serialport::FlowControl::None)
        .timeout(POLL)
        .open()
        .map_err(io::Error::from)?;
    let writer = port.try_clone().map_err(io::Error::from)?;
    Ok((Reader::Serial(port), Writer::Serial(writer)))
}
