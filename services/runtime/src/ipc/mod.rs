//! Every iceoryx2 call of skymesh lives here; the rest sees typed channels.
//!
//! Ports use `ipc_threadsafe::Service` (same shared-memory layout as `ipc::Service`,
//! only the in-process handles are `Send + Sync`) so tokio tasks can own them.
//! A subscriber waits on its topic's event listener through `tokio::io::unix::AsyncFd`:
//! one kernel wake-up per burst, no polling while idle.
//!
//! - `domain`: one mesh's iceoryx2 configuration and its files ([`Domain`]);
//! - `shm`: the room left in `/dev/shm`, checked before a bus opens;
//! - `bus`: a service's node ([`Bus`]) and how a topic's services are opened;
//! - `publisher`, `subscriber`: the typed ports ([`Publisher`], [`Subscriber`]);
//! - `wait`: how a receive waits on its topic's event;
//! - `counts`: a subscriber's per-topic series and gap counting.

use iceoryx2::service::ipc_threadsafe;

mod bus;
mod counts;
mod domain;
mod publisher;
mod shm;
mod subscriber;
mod wait;

pub use bus::Bus;
pub(crate) use bus::{with_qos, with_retry};
pub(crate) use counts::ReceiveCounts;
pub use domain::{
    is_valid_domain, Domain, DomainGuard, DEFAULT_DOMAIN, DOMAIN_ENV, EMBEDDED_IPC_CONFIG,
    IPC_CONFIG_ENV,
};
pub use publisher::Publisher;
pub use shm::{
    check_shm_room, shm_min_free_from_env, shm_space, ShmFull, ShmSpace, SHM_DIR,
    SHM_LOW_FREE_BYTES, SHM_MIN_FREE_BYTES, SHM_MIN_FREE_ENV,
};
pub use subscriber::Subscriber;
pub(crate) use wait::SocketWait;

/// The iceoryx2 service flavour every skymesh process uses.
pub type Svc = ipc_threadsafe::Service;

/// A failure of the shared-memory bus.
#[derive(Debug, thiserror::Error)]
pub enum IpcError {
    #[error("iceoryx2 {op} `{what}` failed: {message}")]
    Iceoryx {
        op: &'static str,
        what: String,
        message: String,
    },
    #[error("waiting on `{topic}`: {source}")]
    Wait {
        topic: String,
        source: std::io::Error,
    },
}

impl IpcError {
    /// For `map_err` on a [`crate::timer`] call that paces a bus loop: the timer
    /// `what` (e.g. "the heartbeat timer") failed.
    pub fn timer(what: &'static str) -> impl Fn(std::io::Error) -> IpcError + Copy {
        move |source| IpcError::Wait {
            topic: what.to_string(),
            source,
        }
    }
}

#[cold]
#[inline(never)]
pub(crate) fn ipc_err(op: &'static str, what: &str, e: impl core::fmt::Debug) -> IpcError {
    IpcError::Iceoryx {
        op,
        what: what.to_string(),
        message: format!("{e:?}"),
    }
}
