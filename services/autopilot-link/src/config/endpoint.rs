//! Where the autopilot and the router endpoints are: the `connection` and
//! `endpoints` strings.

use std::fmt;
use std::net::SocketAddr;

use skymesh_runtime::config::{in_range, socket_addr};
use skymesh_runtime::ConfigError;

/// Where the autopilot is, as written in `connection`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Endpoint {
    /// `tcpout:HOST:PORT`: we connect (ArduPilot SITL, vehicle-sim, a telemetry radio bridge).
    TcpOut { host: String, port: u16 },
    /// `tcpin:IP:PORT`: we listen and take one client at a time.
    TcpIn(SocketAddr),
    /// `udpin:IP:PORT`: we listen; replies go to whoever sent last.
    UdpIn(SocketAddr),
    /// `udpout:HOST:PORT`: we send to the autopilot and read its replies.
    UdpOut { host: String, port: u16 },
    /// `serial:DEVICE:BAUD`: a UART or USB CDC port of the flight controller.
    Serial { device: String, baud: u32 },
}

impl Endpoint {
    /// Parses a connection string, naming `field` in the error.
    pub fn parse(field: &str, s: &str) -> Result<Endpoint, ConfigError> {
        let bad = |msg: String| ConfigError::invalid(field, msg);
        let (scheme, rest) = s.split_once(':').ok_or_else(|| {
            bad(format!(
                "`{s}` has no scheme; use tcpout:, tcpin:, udpin:, udpout: or serial:"
            ))
        })?;
        let host_port = |rest: &str| -> Result<(String, u16), ConfigError> {
            let (host, port) = rest
                .rsplit_once(':')
                .ok_or_else(|| bad(format!("`{s}` needs HOST:PORT after `{scheme}:`")))?;
            let host = host.trim_start_matches('[').trim_end_matches(']');
            if host.is_empty() {
                return Err(bad(format!("`{s}` has an empty host")));
            }
            let port: u16 = port
                .parse()
                .map_err(|_| bad(format!("`{s}`: `{port}` is not a port number")))?;
            if port == 0 {
                return Err(bad(format!("`{s}`: port 0 cannot be connected to")));
            }
            Ok((host.to_string(), port))
        };
        match scheme {
            "tcpout" => {
                let (host, port) = host_port(rest)?;
                Ok(Endpoint::TcpOut { host, port })
            }
            "udpout" => {
                let (host, port) = host_port(rest)?;
                Ok(Endpoint::UdpOut { host, port })
            }
            "tcpin" => Ok(Endpoint::TcpIn(socket_addr(field, rest)?)),
            "udpin" => Ok(Endpoint::UdpIn(socket_addr(field, rest)?)),
            "serial" => {
                // Split at the last colon: device paths may contain colons, baud rates never do.
                let (device, baud) = rest
                    .rsplit_once(':')
                    .ok_or_else(|| bad(format!("`{s}` needs serial:DEVICE:BAUD")))?;
                if device.is_empty() {
                    return Err(bad(format!("`{s}` has an empty device path")));
                }
                let baud: u32 = baud
                    .parse()
                    .map_err(|_| bad(format!("`{s}`: `{baud}` is not a baud rate")))?;
                let baud = in_range(field, baud, 1200, 12_000_000)?;
                Ok(Endpoint::Serial {
                    device: device.to_string(),
                    baud,
                })
            }
            other => Err(bad(format!(
                "unknown scheme `{other}:`; use tcpout:, tcpin:, udpin:, udpout: or serial:"
            ))),
        }
    }

    /// Stream transports end with EOF or an error; datagram ones never do.
    pub fn is_stream(&self) -> bool {
        matches!(
            self,
            Endpoint::TcpOut { .. } | Endpoint::TcpIn(_) | Endpoint::Serial { .. }
        )
    }
}

/// `host:port`, with an IPv6 literal in brackets.
struct HostPort<'a>(&'a str, u16);

impl fmt::Display for HostPort<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.contains(':') {
            write!(f, "[{}]:{}", self.0, self.1)
        } else {
            write!(f, "{}:{}", self.0, self.1)
        }
    }
}

impl fmt::Display for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Endpoint::TcpOut { host, port } => write!(f, "tcpout:{}", HostPort(host, *port)),
            Endpoint::TcpIn(a) => write!(f, "tcpin:{a}"),
            Endpoint::UdpIn(a) => write!(f, "udpin:{a}"),
            Endpoint::UdpOut { host, port } => write!(f, "udpout:{}", HostPort(host, *port)),
            Endpoint::Serial { device, baud } => write!(f, "serial:{device}:{baud}"),
        }
    }
}
/// The `endpoints` list: valid strings, no serial ports, no duplicates, not the
/// autopilot's own connection, at most [`crate::router::MAX_ENDPOINTS`].
pub(super) fn router_endpoints(
    list: &[String],
    connection: &str,
) -> Result<Vec<Endpoint>, ConfigError> {
    const FIELD: &str = "endpoints";
    let max = crate::router::MAX_ENDPOINTS;
    if list.len() > max {
        return Err(ConfigError::invalid(
            FIELD,
            format!("{} endpoints; at most {max}", list.len()),
        ));
    }
    let connection = Endpoint::parse("connection", connection).ok();
    let mut out: Vec<Endpoint> = Vec::new();
    for s in list {
        let e = Endpoint::parse(FIELD, s)?;
        if matches!(e, Endpoint::Serial { .. }) {
            return Err(ConfigError::invalid(
                FIELD,
                format!("`{s}`: serial router endpoints are not supported; use udpin/udpout/tcpin/tcpout"),
            ));
        }
        if out.contains(&e) {
            return Err(ConfigError::invalid(
                FIELD,
                format!("`{s}` is listed twice"),
            ));
        }
        if connection.as_ref() == Some(&e) {
            return Err(ConfigError::invalid(
                FIELD,
                format!("`{s}` is the autopilot connection itself"),
            ));
        }
        out.push(e);
    }
    Ok(out)
}
