//! Which clients may SET: a list of addresses and CIDR networks.
//!
//! The matching is the runtime's [`skymesh_runtime::addresses`] (shared with
//! groundcontrol-gateway's privileged list): an IPv4-mapped IPv6 peer
//! (`::ffff:127.0.0.1`) matches `127.0.0.1`.

pub use skymesh_runtime::addresses::{AddressList, IpNet, IpNetError};

/// The `write_allowed` list.
pub type AddrSet = AddressList;
