//! Which clients are privileged: a list of addresses and CIDR networks.
//!
//! GroundControl takes "a client IP list on startup"; skymesh also accepts networks
//! (`192.168.0.0/24`). The matching is the runtime's [`skymesh_runtime::addresses`]
//! (shared with digiview-gateway's `write_allowed`).

pub use skymesh_runtime::addresses::{AddressList, IpNet, IpNetError};

/// The privileged list.
pub type AddrSet = AddressList;
