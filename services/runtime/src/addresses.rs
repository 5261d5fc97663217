//! A list of IP addresses and CIDR networks that a peer's address is checked against
//! (pure).
//!
//! What it is for: GroundControl's privileged clients (groundcontrol-gateway's
//! `privileged`) and the clients DigiView lets SET (digiview-gateway's
//! `write_allowed`); the IMC peer allow-list (issue 11) can use it too.
//!
//! Entries are addresses (`127.0.0.1`, a /32 or /128) or networks
//! (`192.168.0.0/24`). Addresses compare canonically: an IPv4-mapped IPv6 peer
//! (`::ffff:127.0.0.1`, what a dual-stack listener reports) matches `127.0.0.1`, and
//! an IPv4 entry never matches an IPv6 peer (nor the reverse).

use std::fmt;
use std::net::IpAddr;
use std::str::FromStr;

/// One address (`10.0.0.7`, a /32 or /128) or network (`10.0.0.0/24`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IpNet {
    addr: IpAddr,
    prefix: u8,
}

/// Why an entry of the list does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IpNetError {
    #[error("not an IP address")]
    Address,
    #[error("prefix length must be 0..={max}")]
    Prefix { max: u8 },
}

impl FromStr for IpNet {
    type Err = IpNetError;

    fn from_str(s: &str) -> Result<IpNet, IpNetError> {
        let (addr, prefix) = match s.split_once('/') {
            Some((a, p)) => (a, Some(p)),
            None => (s, None),
        };
        let addr = addr
            .trim()
            .parse::<IpAddr>()
            .map_err(|_| IpNetError::Address)?
            .to_canonical();
        let max = if addr.is_ipv4() { 32 } else { 128 };
        let prefix = match prefix {
            None => max,
            Some(p) => match p.trim().parse::<u8>() {
                Ok(p) if p <= max => p,
                _ => return Err(IpNetError::Prefix { max }),
            },
        };
        Ok(IpNet { addr, prefix })
    }
}

impl IpNet {
    /// Whether `ip` lies in this address or network.
    pub fn contains(&self, ip: IpAddr) -> bool {
        let ip = ip.to_canonical();
        let (net, ip, bits) = match (self.addr, ip) {
            (IpAddr::V4(n), IpAddr::V4(i)) => {
                (u128::from(n.to_bits()), u128::from(i.to_bits()), 32)
            }
            (IpAddr::V6(n), IpAddr::V6(i)) => (n.to_bits(), i.to_bits(), 128),
            _ => return false,
        };
        let host_bits = bits - u32::from(self.prefix);
        if host_bits >= 128 {
            return true;
        }
        (net >> host_bits) == (ip >> host_bits)
    }
}

impl fmt::Display for IpNet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let max = if self.addr.is_ipv4() { 32 } else { 128 };
        if self.prefix == max {
            write!(f, "{}", self.addr)
        } else {
            write!(f, "{}/{}", self.addr, self.prefix)
        }
    }
}

/// An allow-list: an address matches if any entry contains it (an empty list matches
/// nothing).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct AddressList(Vec<IpNet>);

impl AddressList {
    pub fn new(nets: Vec<IpNet>) -> AddressList {
        AddressList(nets)
    }

    /// Whether any entry contains `ip`.
    pub fn contains(&self, ip: IpAddr) -> bool {
        self.0.iter().any(|n| n.contains(ip))
    }

    pub fn entries(&self) -> &[IpNet] {
        &self.0
    }
}

impl fmt::Display for AddressList {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let parts: Vec<String> = self.0.iter().map(ToString::to_string).collect();
        write!(f, "[{}]", parts.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ip(s: &str) -> IpAddr {
        s.parse().unwrap()
    }

    #[test]
    fn addresses_and_networks() {
        let one: IpNet = "127.0.0.1".parse().unwrap();
        assert!(one.contains(ip("127.0.0.1")));
        assert!(one.contains(ip("::ffff:127.0.0.1")));
        assert!(!one.contains(ip("127.0.0.2")));
        let net: IpNet = "192.168.0.0/24".parse().unwrap();
        assert!(net.contains(ip("192.168.0.255")));
        assert!(!net.contains(ip("192.168.1.0")));
        let all: IpNet = "0.0.0.0/0".parse().unwrap();
        assert!(all.contains(ip("8.8.8.8")));
        assert!(!all.contains(ip("::1")));
        let v6: IpNet = "fd00::/8".parse().unwrap();
        assert!(v6.contains(ip("fd12::1")));
        assert!(!v6.contains(ip("fe80::1")));
        assert_eq!(net.to_string(), "192.168.0.0/24");
        assert_eq!(one.to_string(), "127.0.0.1");
    }

    #[test]
    fn bad_entries() {
        assert_eq!("localhost".parse::<IpNet>(), Err(IpNetError::Address));
        assert_eq!(
            "10.0.0.0/33".parse::<IpNet>(),
            Err(IpNetError::Prefix { max: 32 })
        );
        assert_eq!(
            "::/129".parse::<IpNet>(),
            Err(IpNetError::Prefix { max: 128 })
        );
        assert_eq!(
            "10.0.0.0/x".parse::<IpNet>(),
            Err(IpNetError::Prefix { max: 32 })
        );
    }

    #[test]
    fn a_list_matches_any_entry() {
        let list = AddressList::new(vec![
            "192.168.0.0/24".parse().unwrap(),
            "::1".parse().unwrap(),
        ]);
        assert!(list.contains(ip("192.168.0.9")));
        assert!(list.contains(ip("::ffff:192.168.0.9")));
        assert!(list.contains(ip("::1")));
        assert!(!list.contains(ip("127.0.0.1")));
        assert_eq!(list.entries().len(), 2);
        assert_eq!(list.to_string(), "[192.168.0.0/24, ::1]");
        assert!(!AddressList::default().contains(ip("127.0.0.1")));
    }
}
