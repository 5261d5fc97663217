//! Exit codes are a contract with the supervisor and systemd.
//!
//! Only [`CONFIG`] is final: every other non-zero code is restarted with backoff
//! (`skymesh up`'s restart policy; `Restart=on-failure` under systemd). The distinct
//! codes tell the operator (and `skymesh status`) why without reading the log.

/// Clean exit (SIGTERM handled, work finished).
pub const OK: u8 = 0;
/// Runtime failure: restarted with backoff.
pub const FAILURE: u8 = 1;
/// Bad configuration (`EX_USAGE`): never restarted, state `config-error`.
pub const CONFIG: u8 = 64;
/// A shared-memory segment could not be created: `/dev/shm` has too little room
/// (`EX_CANTCREAT`). Restarted with backoff: it clears when room is made.
pub const SHM_FULL: u8 = 73;
/// An address to listen on is in use by another program (`EX_TEMPFAIL`). Restarted
/// with backoff: it clears when the other program goes away.
pub const ADDR_IN_USE: u8 = 75;

/// The exit code for a service that failed with `error`: [`ADDR_IN_USE`] if any
/// cause in its chain is an `EADDRINUSE`, else [`FAILURE`].
pub fn code_for(error: &anyhow::Error) -> u8 {
    if is_addr_in_use(error) {
        ADDR_IN_USE
    } else {
        FAILURE
    }
}

/// True if any cause in `error`'s chain is an I/O error of kind `AddrInUse`.
pub fn is_addr_in_use(error: &anyhow::Error) -> bool {
    error.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == std::io::ErrorKind::AddrInUse)
    })
}

/// What an exit code means, for logs (`None` for codes this contract does not name).
pub fn meaning(code: i32) -> Option<&'static str> {
    Some(match u8::try_from(code).ok()? {
        OK => "clean exit",
        FAILURE => "runtime failure",
        CONFIG => "bad configuration",
        SHM_FULL => "shared memory (/dev/shm) full",
        ADDR_IN_USE => "address already in use",
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use anyhow::Context;

    #[test]
    fn a_port_in_use_anywhere_in_the_chain_is_its_own_code() {
        let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = held.local_addr().unwrap();
        let e = std::net::TcpListener::bind(addr)
            .with_context(|| format!("binding the app listener on tcp {addr}"))
            .context("starting")
            .unwrap_err();
        assert_eq!(code_for(&e), ADDR_IN_USE);
        assert!(format!("{e:#}").contains(&addr.to_string()), "{e:#}");

        #[derive(Debug, thiserror::Error)]
        #[error("cannot listen on {addr}: {source}")]
        struct Listen {
            addr: std::net::SocketAddr,
            source: std::io::Error,
        }
        let udp = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let addr = udp.local_addr().unwrap();
        let source = std::net::UdpSocket::bind(addr).unwrap_err();
        let e = anyhow::Error::new(Listen { addr, source });
        assert_eq!(code_for(&e), ADDR_IN_USE);

        assert_eq!(code_for(&anyhow::anyhow!("bus failed")), FAILURE);
        assert_ne!(ADDR_IN_USE, CONFIG);
        assert_ne!(SHM_FULL, CONFIG);
        assert_eq!(meaning(75), Some("address already in use"));
        assert_eq!(meaning(2), None);
    }
}
