//! Every iceoryx2 call of skymesh lives here; the rest sees typed channels.
//!
//! Ports use `ipc_threadsafe::Service` (same shared-memory layout as `ipc::Service`,
//! only the in-process handles are `Send + Sync`) so tokio tasks can own them.
//! A subscriber waits on its topic's event listener through `tokio::io::unix::AsyncFd`:
//! one kernel wake-up per burst, no polling while idle.

use std::os::fd::{AsRawFd, BorrowedFd, RawFd};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use iceoryx2::config::Config;
use iceoryx2::node::NodeView;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use iceoryx2::service::ipc_threadsafe;
use skymesh_ipc_types::{Sample, SampleHeader, ServiceId, Topic};
use tokio::io::unix::AsyncFd;

use crate::clock::monotonic_ns;
use crate::config::ConfigError;
use crate::stats::{Counter, Histogram, Stats, LATENCY_BOUNDS_S};

/// The iceoryx2 service flavour every skymesh process uses.
pub type Svc = ipc_threadsafe::Service;

/// Environment variable naming the mesh's domain (iceoryx2 resource prefix).
pub const DOMAIN_ENV: &str = "SKYMESH_DOMAIN";
/// Environment variable naming the iceoryx2 config file.
pub const IPC_CONFIG_ENV: &str = "SKYMESH_IPC_CONFIG";
/// The domain when `SKYMESH_DOMAIN` is unset.
pub const DEFAULT_DOMAIN: &str = "skymesh";
/// `deploy/iceoryx2.toml`, used when no file is named.
pub const EMBEDDED_IPC_CONFIG: &str = include_str!("../../../deploy/iceoryx2.toml");

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

/// Where POSIX shared memory (every iceoryx2 segment) lives on Linux.
pub const SHM_DIR: &str = "/dev/shm";
/// Environment variable overriding [`SHM_MIN_FREE_BYTES`] (bytes; 0 turns the check off).
pub const SHM_MIN_FREE_ENV: &str = "SKYMESH_SHM_MIN_FREE_BYTES";
/// A service refuses to start (exit [`crate::exit::SHM_FULL`]) with less room than
/// this in [`SHM_DIR`]: iceoryx2 maps its segments sparsely and touches the pages
/// later, and a page that cannot be backed then kills the process with SIGBUS. One
/// service's segments take a few hundred KiB up to tens of MiB (camera frames).
pub const SHM_MIN_FREE_BYTES: u64 = 4 << 20;
/// Below this much room a starting service warns: size `/dev/shm` up.
pub const SHM_LOW_FREE_BYTES: u64 = 64 << 20;

/// Room in a shared-memory file system.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShmSpace {
    /// Bytes an unprivileged process can still allocate.
    pub free: u64,
    /// Size of the file system.
    pub size: u64,
}

/// The room in `dir` (normally [`SHM_DIR`]), by `statvfs`.
// The statvfs field types are u64 here but u32 on 32-bit targets.
#[allow(clippy::useless_conversion)]
pub fn shm_space(dir: &Path) -> std::io::Result<ShmSpace> {
    let st = nix::sys::statvfs::statvfs(dir).map_err(std::io::Error::from)?;
    let frag = u64::from(st.fragment_size());
    Ok(ShmSpace {
        free: u64::from(st.blocks_available()).saturating_mul(frag),
        size: u64::from(st.blocks()).saturating_mul(frag),
    })
}

/// `dir` has less room than a service needs to open its bus.
#[derive(Debug, thiserror::Error)]
#[error(
    "shared memory {dir} is full: {free} bytes free of {size}, need at least {need} \
     (make room or size it up, e.g. `mount -o remount,size=256m {dir}`; \
     ${SHM_MIN_FREE_ENV} sets the minimum)",
    dir = dir.display()
)]
pub struct ShmFull {
    pub dir: PathBuf,
    pub free: u64,
    pub size: u64,
    pub need: u64,
}

/// Checked before the bus is opened: `Err` if `dir` has less than `need` bytes free
/// (creating segments there could end in SIGBUS instead of an error), else its room.
/// A `dir` that cannot be examined is not an error (`Ok(None)`): iceoryx2 reports it.
pub fn check_shm_room(dir: &Path, need: u64) -> Result<Option<ShmSpace>, ShmFull> {
    let Ok(space) = shm_space(dir) else {
        return Ok(None);
    };
    if space.free < need {
        return Err(ShmFull {
            dir: dir.to_path_buf(),
            free: space.free,
            size: space.size,
            need,
        });
    }
    Ok(Some(space))
}

/// The minimum room from `$SKYMESH_SHM_MIN_FREE_BYTES` (bytes), else [`SHM_MIN_FREE_BYTES`].
pub fn shm_min_free_from_env() -> Result<u64, ConfigError> {
    match std::env::var(SHM_MIN_FREE_ENV) {
        Ok(v) if !v.trim().is_empty() => v.trim().parse().map_err(|_| ConfigError::Env {
            name: SHM_MIN_FREE_ENV,
            message: format!("`{v}` is not a number of bytes"),
        }),
        _ => Ok(SHM_MIN_FREE_BYTES),
    }
}

/// One mesh's iceoryx2 configuration: the loaded config file with the domain prefix applied.
#[derive(Debug, Clone)]
pub struct Domain {
    pub name: String,
    pub config: Config,
    /// Where the config came from (file path or `<embedded>`), for logs.
    pub origin: String,
}

/// True if `name` can be a domain (it prefixes file names in `/dev/shm`).
pub fn is_valid_domain(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 24
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

impl Domain {
    /// Loads the iceoryx2 config (`path`, else `$SKYMESH_IPC_CONFIG`, else the embedded
    /// `deploy/iceoryx2.toml`) and applies the domain from `$SKYMESH_DOMAIN`.
    pub fn from_env(path: Option<&Path>) -> Result<Domain, ConfigError> {
        let name = match std::env::var(DOMAIN_ENV) {
            Ok(v) if !v.is_empty() => v,
            _ => DEFAULT_DOMAIN.to_string(),
        };
        let path: Option<PathBuf> = path
            .map(Path::to_path_buf)
            .or_else(|| std::env::var_os(IPC_CONFIG_ENV).map(PathBuf::from));
        Domain::load(&name, path.as_deref())
    }

    /// Loads the config for domain `name` from `path` (or the embedded default).
    pub fn load(name: &str, path: Option<&Path>) -> Result<Domain, ConfigError> {
        if !is_valid_domain(name) {
            return Err(ConfigError::Env {
                name: DOMAIN_ENV,
                message: format!("`{name}` must be 1-24 characters of [A-Za-z0-9_-]"),
            });
        }
        let (text, origin) = match path {
            Some(p) => (
                std::fs::read_to_string(p).map_err(|source| ConfigError::Read {
                    path: p.to_path_buf(),
                    source,
                })?,
                p.display().to_string(),
            ),
            None => (
                EMBEDDED_IPC_CONFIG.to_string(),
                "<embedded deploy/iceoryx2.toml>".to_string(),
            ),
        };
        let mut config: Config = toml::from_str(&text).map_err(|e| ConfigError::Ipc {
            origin: origin.clone(),
            message: e.to_string(),
        })?;
        config.global.prefix =
            FileName::new(format!("{name}_").as_bytes()).map_err(|e| ConfigError::Ipc {
                origin: origin.clone(),
                message: format!("domain prefix: {e:?}"),
            })?;
        Ok(Domain {
            name: name.to_string(),
            config,
            origin,
        })
    }

    /// The prefix of every iceoryx2 file of this domain.
    pub fn prefix(&self) -> String {
        format!("{}_", self.name)
    }

    /// Removes the stale resources of every dead node of this domain. Returns the
    /// names of the nodes cleaned and how many could not be.
    ///
    /// A dead node is only recognisable once its process has been reaped, so the
    /// supervisor calls this after `waitpid`.
    pub fn cleanup_dead_nodes(&self) -> (Vec<String>, usize) {
        cleanup_dead::<Svc>(&self.config)
    }

    /// Names and pids of the live nodes of this domain.
    pub fn live_nodes(&self) -> Vec<(String, i32)> {
        let mut out = Vec::new();
        let _ = Node::<Svc>::list(&self.config, |state| {
            if let NodeState::Alive(view) = state {
                if let Some(d) = view.details() {
                    out.push((d.name().as_str().to_string(), d.process_id().value()));
                }
            }
            CallbackProgression::Continue
        });
        out
    }

    /// Files this domain left in `/dev/shm` and under the iceoryx2 root path.
    pub fn leftover_files(&self) -> Vec<PathBuf> {
        let prefix = self.prefix();
        let root = PathBuf::from(self.config.global.root_path().to_string());
        let mut dirs = vec![PathBuf::from("/dev/shm")];
        for sub in ["", "services", "nodes"] {
            dirs.push(root.join(sub));
        }
        let mut out = Vec::new();
        let mut stack: Vec<PathBuf> = dirs;
        while let Some(dir) = stack.pop() {
            let Ok(rd) = std::fs::read_dir(&dir) else {
                continue;
            };
            for entry in rd.flatten() {
                let name = entry.file_name();
                let name = name.to_string_lossy();
                if name.starts_with(prefix.as_str()) {
                    out.push(entry.path());
                }
            }
        }
        out.sort();
        out.dedup();
        out
    }

    /// Removes [`Domain::leftover_files`]. Only call when no node of the domain is alive.
    pub fn remove_leftover_files(&self) -> usize {
        let mut removed = 0;
        for path in self.leftover_files() {
            let res = if path.is_dir() {
                std::fs::remove_dir_all(&path)
            } else {
                std::fs::remove_file(&path)
            };
            match res {
                Ok(()) => removed += 1,
                Err(e) => {
                    tracing::warn!(path = %path.display(), error = %e, "cannot remove leftover file")
                }
            }
        }
        removed
    }
}

/// A domain whose shared-memory files are removed when this is dropped, however a
/// test or a benchmark ends (declare it before the buses of the domain: locals drop
/// in reverse order, so the nodes are gone first).
#[derive(Debug)]
pub struct DomainGuard(pub Domain);

impl std::ops::Deref for DomainGuard {
    type Target = Domain;
    fn deref(&self) -> &Domain {
        &self.0
    }
}

impl Drop for DomainGuard {
    fn drop(&mut self) {
        self.remove_leftover_files();
    }
}

/// Removes the stale resources of every dead node of service kind `S` under
/// `config`; the names cleaned and how many could not be.
fn cleanup_dead<S: iceoryx2::service::Service>(config: &Config) -> (Vec<String>, usize) {
    let mut cleaned = Vec::new();
    let mut failed = 0;
    let result = Node::<S>::list(config, |state| {
        if let NodeState::Dead(view) = state {
            let name = view
                .details()
                .as_ref()
                .map(|d| d.name().as_str().to_string())
                .unwrap_or_default();
            match view.try_remove_stale_resources() {
                Ok(()) => cleaned.push(name),
                Err(e) => {
                    tracing::warn!(node = %name, error = ?e, "stale node cleanup failed");
                    failed += 1;
                }
            }
        }
        CallbackProgression::Continue
    });
    if let Err(e) = result {
        tracing::warn!(error = ?e, "listing iceoryx2 nodes failed");
    }
    (cleaned, failed)
}

/// `topic`'s event service of service kind `S` on `node`, created if needed.
fn open_event_of<S: iceoryx2::service::Service>(
    node: &Node<S>,
    topic: &Topic,
    op: &'static str,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<S>, IpcError> {
    let service_name =
        ServiceName::new(&topic.name).map_err(|e| ipc_err("service name", &topic.name, e))?;
    with_retry(node, &topic.name, op, || {
        node.service_builder(&service_name)
            .event()
            .max_listeners(topic.qos.event_listeners())
            .max_notifiers(topic.qos.event_notifiers())
            .max_nodes(topic.qos.max_nodes)
            // One event id (0): a listener's drain resets every id's counter in
            // shared memory, 256 atomic swaps over 2 KiB with iceoryx2's default
            // (255) — per wake-up, in every process.
            .event_id_max_value(0)
            .open_or_create()
    })
}

struct BusInner {
    node: Node<Svc>,
    name: String,
    service: ServiceId,
    instance: u16,
    stats: Stats,
}

/// A service's handle on the mesh: its iceoryx2 node plus the stats registry that
/// counts every sample in and out. Cheap to clone.
#[derive(Clone)]
pub struct Bus {
    inner: Arc<BusInner>,
}

impl core::fmt::Debug for Bus {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Bus")
            .field("name", &self.inner.name)
            .field("service", &self.inner.service)
            .finish()
    }
}

/// Retries `open` a few times, cleaning dead nodes in between: many processes
/// restarting at once can race stale-resource cleanup (iceoryx2 issue #1578).
pub(crate) fn with_retry<S: iceoryx2::service::Service, T, E: core::fmt::Debug>(
    node: &Node<S>,
    what: &str,
    op: &'static str,
    mut open: impl FnMut() -> Result<T, E>,
) -> Result<T, IpcError> {
    let mut delay = Duration::from_millis(20);
    let mut attempt = 0;
    loop {
        match open() {
            Ok(v) => return Ok(v),
            Err(e) if attempt < 5 => {
                tracing::debug!(what, op, error = ?e, attempt, "iceoryx2 open failed, cleaning dead nodes and retrying");
                let _ = node.try_cleanup_dead_nodes();
                std::thread::sleep(delay);
                delay *= 2;
                attempt += 1;
            }
            Err(e) => return Err(ipc_err(op, what, e)),
        }
    }
}

/// `topic`'s publish-subscribe service, opened (or created) through `node`.
fn open_pubsub_on<T: Sample>(
    node: &Node<Svc>,
    topic: &Topic,
) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, T, ()>, IpcError> {
    let service_name =
        ServiceName::new(&topic.name).map_err(|e| ipc_err("service name", &topic.name, e))?;
    with_retry(node, &topic.name, "open publish-subscribe", || {
        with_qos(
            node.service_builder(&service_name).publish_subscribe::<T>(),
            topic,
        )
        .open_or_create()
    })
}

/// A publish-subscribe service's settings from `topic`'s QoS: every topic's, samples
/// and frames alike (a newest-first ring: a slow subscriber loses the oldest).
pub(crate) fn with_qos<P, H, S>(
    builder: iceoryx2::service::builder::publish_subscribe::Builder<P, H, S>,
    topic: &Topic,
) -> iceoryx2::service::builder::publish_subscribe::Builder<P, H, S>
where
    P: core::fmt::Debug + IceoryxSend + ?Sized,
    H: core::fmt::Debug + ZeroCopySend,
    S: iceoryx2::service::Service,
{
    let q = topic.qos;
    builder
        .max_publishers(q.max_publishers)
        .max_subscribers(q.max_subscribers)
        .max_nodes(q.max_nodes)
        .history_size(q.history)
        .subscriber_max_buffer_size(q.buffer)
        .enable_safe_overflow(true)
}

impl Bus {
    /// Creates the node `name` in `domain`. Signal handling stays with the caller.
    pub fn open(
        domain: &Domain,
        name: &str,
        service: ServiceId,
        instance: u16,
        stats: Stats,
    ) -> Result<Bus, IpcError> {
        let node_name = NodeName::new(name).map_err(|e| ipc_err("node name", name, e))?;
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(&domain.config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<Svc>()
            .map_err(|e| ipc_err("create node", name, e))?;
        Ok(Bus {
            inner: Arc::new(BusInner {
                node,
                name: name.to_string(),
                service,
                instance,
                stats,
            }),
        })
    }

    pub fn name(&self) -> &str {
        &self.inner.name
    }

    /// The iceoryx2 node, for the other port kinds of this crate (frames).
    pub(crate) fn node(&self) -> &Node<Svc> {
        &self.inner.node
    }

    pub fn stats(&self) -> &Stats {
        &self.inner.stats
    }

    /// The header fields every publisher of this bus stamps (`service`, `instance`;
    /// sequence and time zero): what an answer addressed to this process carries
    /// (e.g. `HardwareReply::answers`).
    pub fn origin(&self) -> SampleHeader {
        SampleHeader {
            service: self.inner.service.to_wire(),
            instance: self.inner.instance,
            ..SampleHeader::default()
        }
    }

    pub(crate) fn open_event(
        &self,
        topic: &Topic,
    ) -> Result<iceoryx2::service::port_factory::event::PortFactory<Svc>, IpcError> {
        open_event_of(&self.inner.node, topic, "open event")
    }

    /// A publisher's notifier of `topic`'s event (with nobody waiting, a notify is
    /// a few atomic operations).
    pub(crate) fn notifier(&self, topic: &Topic) -> Result<Notifier<Svc>, IpcError> {
        self.open_event(topic)?
            .notifier_builder()
            .create()
            .map_err(|e| ipc_err("create notifier", &topic.name, e))
    }

    fn open_pubsub<T: Sample>(
        &self,
        topic: &Topic,
    ) -> Result<iceoryx2::service::port_factory::publish_subscribe::PortFactory<Svc, T, ()>, IpcError>
    {
        open_pubsub_on(&self.inner.node, topic)
    }

    /// A publisher on `topic` that stamps headers, sends and wakes subscribers.
    pub fn publisher<T: Sample>(&self, topic: &Topic) -> Result<Publisher<T>, IpcError> {
        self.publisher_counted_as(topic, &topic.name)
    }

    /// A publisher whose metrics carry `topic="<family>"` instead of its own name:
    /// for a process with one port per vehicle of a large swarm, so e.g. 250
    /// `skymesh/vehicle/{id}/command` ports are one series
    /// (`skymesh/vehicle/*/command`) and fit the stats sample.
    pub fn publisher_counted_as<T: Sample>(
        &self,
        topic: &Topic,
        family: &str,
    ) -> Result<Publisher<T>, IpcError> {
        let pubsub = self.open_pubsub::<T>(topic)?;
        let port = pubsub
            .publisher_builder()
            .create()
            .map_err(|e| ipc_err("create publisher", &topic.name, e))?;
        let notifier = self.notifier(topic)?;
        let published = self.inner.stats.counter(
            "skymesh_topic_samples_published_total",
            &[("topic", family)],
        );
        Ok(Publisher {
            port,
            notifier,
            seq: 0,
            service: self.inner.service.to_wire(),
            instance: self.inner.instance,
            published,
            topic: topic.name.clone(),
            _bus: self.clone(),
        })
    }

    /// A subscriber on `topic`: awaited with `recv` (inside a tokio runtime) or
    /// polled with `try_recv`.
    pub fn subscriber<T: Sample>(&self, topic: &Topic) -> Result<Subscriber<T>, IpcError> {
        self.subscriber_counted_as(topic, &topic.name)
    }

    /// A subscriber whose metrics carry `topic="<family>"` (see
    /// [`Bus::publisher_counted_as`]); gaps are still counted per port.
    pub fn subscriber_counted_as<T: Sample>(
        &self,
        topic: &Topic,
        family: &str,
    ) -> Result<Subscriber<T>, IpcError> {
        let pubsub = self.open_pubsub::<T>(topic)?;
        let event = self.open_event(topic)?;
        let port = pubsub
            .subscriber_builder()
            .create()
            .map_err(|e| ipc_err("create subscriber", &topic.name, e))?;
        let socket = SocketWait::new(event, &topic.name)?;
        Ok(Subscriber {
            socket,
            port,
            counts: ReceiveCounts::new(&self.inner.stats, family),
            topic: topic.name.clone(),
            _bus: self.clone(),
        })
    }
}

/// The listener's file descriptor, registered with tokio's reactor.
///
/// Holds only the number; the fd is owned by the [`Listener`], which outlives the
/// registration because [`SocketWait`] declares `afd` before `listener` (fields drop
/// in declaration order, so epoll deregistration happens before the fd closes).
#[derive(Debug)]
pub(crate) struct ListenerFd(RawFd);

impl AsRawFd for ListenerFd {
    fn as_raw_fd(&self) -> RawFd {
        self.0
    }
}

/// The listener's file descriptor, borrowed for as long as the listener.
#[allow(unsafe_code)]
fn listener_fd(listener: &Listener<Svc>) -> BorrowedFd<'_> {
    // SAFETY: the fd belongs to `listener`, which keeps it open for its whole life and
    // never replaces it (iceoryx2 documents the fd as fixed for the port's lifetime);
    // the returned borrow cannot outlive `listener`. We never close it.
    unsafe { BorrowedFd::borrow_raw(listener.file_descriptor().native_handle()) }
}

/// Registers the listener's fd with tokio's reactor.
#[allow(unsafe_code)]
pub(crate) fn register_listener(listener: &Listener<Svc>) -> std::io::Result<AsyncFd<ListenerFd>> {
    let fd = ListenerFd(listener_fd(listener).as_raw_fd());
    // SAFETY: the registration requires the fd to stay open, and not be closed by us,
    // for as long as it is registered. We never close it, and the `AsyncFd` holding it
    // is dropped before the `Listener` that owns the fd (`SocketWait`'s field order
    // and `release`).
    Ok(unsafe { AsyncFd::register_with_interest(fd, tokio::io::Interest::READABLE) }?)
}

/// A subscriber's wait on its topic's event: the listener and its tokio
/// registration.
#[derive(Debug)]
pub(crate) struct SocketWait {
    // Declared first: must drop before `listener` (see `ListenerFd`). Registered
    // with tokio on the first wait.
    afd: Option<AsyncFd<ListenerFd>>,
    /// What the receives know about the listener's notifications.
    pub(crate) notes: Notifications,
    listener: Listener<Svc>,
}

impl SocketWait {
    pub(crate) fn new(
        event: iceoryx2::service::port_factory::event::PortFactory<Svc>,
        topic: &str,
    ) -> Result<SocketWait, IpcError> {
        let listener = event
            .listener_builder()
            .create()
            .map_err(|e| ipc_err("create listener", topic, e))?;
        Ok(SocketWait {
            afd: None,
            notes: Notifications::default(),
            listener,
        })
    }

    /// [`Notifications::settle_async`] on this listener.
    pub(crate) fn settle_async(&self, topic: &str) -> Result<(), IpcError> {
        self.notes
            .settle_async(self.afd.as_ref(), &self.listener, topic)
    }

    /// Waits until samples may be pending (see [`wait_listener`]).
    pub(crate) async fn wait_async(&mut self, topic: &str) -> Result<(), IpcError> {
        wait_listener(&mut self.afd, &self.notes, &self.listener, topic).await
    }
}

/// Whether a listener's notifications have been consumed since it last woke.
///
/// iceoryx2's notifier writes to the listener's socket only when the listener's
/// shared notification state is idle: after one notification, later ones are skipped
/// until the listener drains (`try_wait`: state back to idle, one datagram read). The
/// drain therefore need not follow the wake-up at once: a woken receive takes its
/// sample and returns; the next receive drains first ([`Notifications::settle_async`]),
/// then looks for samples, then waits (this keeps the drain's `recvfrom` and event
/// bookkeeping, ~3–5 µs after an idle period, off every sample's latency, at the
/// same two looks and one drain per sample; `scripts/wake-stages.sh`,
/// docs/benchmarks.md). A sample published after the drain notifies anew, so none
/// can slip between that look and the block; a wait that finds the listener woken
/// but no sample (a spurious wake-up) drains, returns, and the caller looks again.
///
/// It also remembers a look that found the queue empty after a drain
/// ([`Notifications::known_empty`]): until the listener wakes again, no notified
/// sample can be waiting, so an async receive polled again for another reason (a
/// `select!` loop re-creates every branch's `recv` future whenever any branch
/// fires) need not look at shared memory. autopilot-link's loop made ~5.5 such
/// empty looks per telemetry read, 18 % of its instructions (callgrind).
#[derive(Debug)]
pub(crate) struct Notifications {
    drained: AtomicBool,
    /// A look after the last drain found nothing, and nothing woke since.
    empty: AtomicBool,
}

impl Default for Notifications {
    fn default() -> Notifications {
        // A new listener may hold a notification already: the first wait drains.
        Notifications {
            drained: AtomicBool::new(false),
            empty: AtomicBool::new(false),
        }
    }
}

impl Notifications {
    /// Drains `listener` unless that was done since its last wake-up; true if it
    /// drained, after which the caller must look for samples before waiting.
    fn drain_first(&self, listener: &Listener<Svc>, topic: &str) -> Result<bool, IpcError> {
        if self.drained.swap(true, Ordering::AcqRel) {
            return Ok(false);
        }
        self.drain(listener, topic)?;
        Ok(true)
    }

    /// At the start of a receive: drains if the listener woke since the last drain
    /// (its sample was taken, its notification left unread). Looking for samples
    /// after this and before a wait is then enough: anything published later
    /// notifies anew. Also clears the reactor's readiness the drain used up (or the
    /// next wait would return at once for nothing). Never waits.
    pub(crate) fn settle_async(
        &self,
        afd: Option<&AsyncFd<ListenerFd>>,
        listener: &Listener<Svc>,
        topic: &str,
    ) -> Result<(), IpcError> {
        if self.drained.load(Ordering::Acquire) {
            return Ok(());
        }
        let guard = match afd {
            Some(afd) => {
                let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
                match afd.poll_read_ready(&mut cx) {
                    std::task::Poll::Ready(Ok(guard)) => Some(guard),
                    std::task::Poll::Ready(Err(source)) => {
                        return Err(IpcError::Wait {
                            topic: topic.to_string(),
                            source,
                        })
                    }
                    std::task::Poll::Pending => None,
                }
            }
            None => None,
        };
        self.drain(listener, topic)?;
        if let Some(mut guard) = guard {
            guard.clear_ready();
        }
        Ok(())
    }

    /// Consumes the listener's pending notifications now.
    pub(crate) fn drain(&self, listener: &Listener<Svc>, topic: &str) -> Result<(), IpcError> {
        self.drained.store(true, Ordering::Release);
        // The notifications just consumed may be for samples nobody looked at yet.
        self.empty.store(false, Ordering::Release);
        listener
            .try_wait(|_| {})
            .map_err(|e| ipc_err("listener wait", topic, e))?;
        Ok(())
    }

    /// The listener woke (or a sample was taken without waiting, whose notification
    /// may be pending): the next wait drains before it blocks.
    pub(crate) fn woke(&self) {
        self.drained.store(false, Ordering::Release);
        self.empty.store(false, Ordering::Release);
    }

    /// A look for samples found none. If the listener was drained before it and has
    /// not woken since, every sample published from now on notifies anew (the drain
    /// re-armed the notifier), so the queue is known to be empty until then.
    fn looked_empty(&self) {
        if self.drained.load(Ordering::Acquire) {
            self.empty.store(true, Ordering::Release);
        }
    }

    /// True while the queue is known to be empty (see [`Notifications::looked_empty`]):
    /// the next sample comes with a wake-up, so a receive can wait without looking.
    /// Samples published without notifying (`Publisher::publish_quiet`) are not
    /// seen until then, which is what quiet means.
    fn known_empty(&self) -> bool {
        self.empty.load(Ordering::Acquire)
    }

    /// One look for a sample with `take`, unless the queue is known to be empty
    /// (then `None` without touching shared memory); a look that finds nothing is
    /// remembered (see [`Notifications::looked_empty`]).
    fn look<R>(
        &self,
        take: impl FnOnce() -> Result<Option<R>, IpcError>,
    ) -> Result<Option<R>, IpcError> {
        if self.known_empty() {
            return Ok(None);
        }
        let got = take()?;
        if got.is_none() {
            self.looked_empty();
        }
        Ok(got)
    }
}
/// Waits until samples may be pending on `listener` (see [`Notifications`]): drains
/// the last wake-up's notification and returns at once, or waits for the event to
/// fire. Registers the listener with tokio (in `afd`) on first use. The owner must
/// declare `afd` before `listener` (see [`ListenerFd`]).
pub(crate) async fn wait_listener(
    afd: &mut Option<AsyncFd<ListenerFd>>,
    notes: &Notifications,
    listener: &Listener<Svc>,
    topic: &str,
) -> Result<(), IpcError> {
    let wait_err = |source| IpcError::Wait {
        topic: topic.to_string(),
        source,
    };
    let afd = match afd {
        Some(afd) => afd,
        None => afd.insert(register_listener(listener).map_err(wait_err)?),
    };
    // Undrained after a wake-up, the readiness is still set and this returns at once.
    let mut guard = afd.readable().await.map_err(wait_err)?;
    if notes.drain_first(listener, topic)? {
        // The drain read the socket, so the readiness is used up: clearing it saves
        // the next wait a useless wake-up. A notification arriving after that read
        // is a new edge, which the reactor reports again (tokio only clears the
        // readiness it handed out).
        guard.clear_ready();
    } else {
        // A new edge since the drain: leave it set (and the notification unread)
        // until the receive finds nothing more.
        notes.woke();
    }
    Ok(())
}

/// The last sequence number seen from each publisher `(service, instance)` of a
/// topic, for gap counting: a topic has one or a few publishers, so the first
/// [`SeqTable::INLINE`] live in the subscriber itself (no allocation for a receive to
/// miss in the cache after an idle period) and are scanned without hashing.
#[derive(Debug, Default)]
pub(crate) struct SeqTable {
    inline: [((u16, u16), u64); SeqTable::INLINE],
    len: usize,
    more: Vec<((u16, u16), u64)>,
}

impl SeqTable {
    const INLINE: usize = 4;

    /// Records `seq` as `publisher`'s last; returns the one before, if any.
    pub(crate) fn replace(&mut self, publisher: (u16, u16), seq: u64) -> Option<u64> {
        let (inline, more) = (&mut self.inline[..self.len], &mut self.more);
        if let Some((_, last)) = inline
            .iter_mut()
            .chain(more.iter_mut())
            .find(|(k, _)| *k == publisher)
        {
            return Some(std::mem::replace(last, seq));
        }
        if self.len < Self::INLINE {
            self.inline[self.len] = (publisher, seq);
            self.len += 1;
        } else {
            self.more.push((publisher, seq));
        }
        None
    }
}

/// A subscriber's per-topic series and gap counting, for [`Subscriber`] and
/// [`crate::FrameSubscriber`].
pub(crate) struct ReceiveCounts {
    received: Counter,
    lost: Counter,
    age: Histogram,
    /// Last sequence seen per publisher, for gap counting. Behind a mutex so reads
    /// work through `&self` (`try_recv` takes `&self`); never contended in practice.
    last_seq: Mutex<SeqTable>,
    /// Overwritten samples are expected, not lost (see `set_newest_only`).
    newest_only: bool,
}

impl ReceiveCounts {
    /// The series `topic="<family>"` in `stats`.
    pub(crate) fn new(stats: &Stats, family: &str) -> ReceiveCounts {
        let labels = [("topic", family)];
        ReceiveCounts {
            received: stats.counter("skymesh_topic_samples_received_total", &labels),
            lost: stats.counter("skymesh_topic_samples_lost_total", &labels),
            age: stats.histogram(
                "skymesh_topic_sample_age_seconds",
                &labels,
                &LATENCY_BOUNDS_S,
            ),
            last_seq: Mutex::default(),
            newest_only: false,
        }
    }

    /// Counts a received sample: its age, and the samples its publisher sent
    /// before it that this subscriber never saw.
    pub(crate) fn count(&self, h: &SampleHeader) {
        self.received.inc();
        self.age.observe(h.age_ns(monotonic_ns()) as f64 / 1e9);
        let prev = self
            .last_seq
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .replace((h.service, h.instance), h.seq);
        if let Some(prev) = prev {
            // A lower sequence means the publisher restarted; not a loss.
            if h.seq > prev + 1 && !self.newest_only {
                self.lost.add(h.seq - prev - 1);
            }
        }
    }
}

/// Takes one pending sample from `port` as a copy.
fn take<T: Sample>(
    port: &iceoryx2::port::subscriber::Subscriber<Svc, T, ()>,
    topic: &str,
) -> Result<Option<T>, IpcError> {
    let Some(sample) = port.receive().map_err(|e| ipc_err("receive", topic, e))? else {
        return Ok(None);
    };
    let value: T = *sample.payload();
    drop(sample);
    Ok(Some(value))
}

/// Sends samples of one type on one topic.
pub struct Publisher<T: Sample> {
    port: iceoryx2::port::publisher::Publisher<Svc, T, ()>,
    notifier: Notifier<Svc>,
    seq: u64,
    service: u16,
    instance: u16,
    published: Counter,
    topic: String,
    _bus: Bus,
}

impl<T: Sample> core::fmt::Debug for Publisher<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Publisher")
            .field("topic", &self.topic)
            .field("seq", &self.seq)
            .finish()
    }
}

impl<T: Sample> Publisher<T> {
    /// Stamps the header (sequence, monotonic time, publisher id), sends, and wakes
    /// the subscribers. Returns the sequence number used.
    pub fn publish(&mut self, sample: T) -> Result<u64, IpcError> {
        self.send(sample, true)
    }

    /// Like [`Publisher::publish`] but without waking anyone: for samples the
    /// subscribers look at on their own schedule (a periodic heartbeat the
    /// supervisor drains once a second), which would otherwise cost each of them a
    /// wake-up per sample.
    pub fn publish_quiet(&mut self, sample: T) -> Result<u64, IpcError> {
        self.send(sample, false)
    }

    fn send(&mut self, mut sample: T, wake: bool) -> Result<u64, IpcError> {
        self.seq += 1;
        let h = sample.header_mut();
        h.seq = self.seq;
        h.stamp_ns = monotonic_ns();
        h.service = self.service;
        h.instance = self.instance;
        self.port
            .send_copy(sample)
            .map_err(|e| ipc_err("send", &self.topic, e))?;
        self.sent(wake)
    }

    fn sent(&mut self, wake: bool) -> Result<u64, IpcError> {
        if wake {
            self.notifier
                .notify()
                .map_err(|e| ipc_err("notify", &self.topic, e))?;
        }
        self.published.inc();
        Ok(self.seq)
    }

    /// Like [`Publisher::publish`], but `fill` writes the sample in place in shared
    /// memory (starting from `T::default()`): for large samples (the stats sample is
    /// ~130 KiB) that must not be copied through the stack.
    pub fn publish_with(&mut self, fill: impl FnOnce(&mut T)) -> Result<u64, IpcError> {
        self.send_with(fill, true)
    }

    /// [`Publisher::publish_with`] without waking anyone (see
    /// [`Publisher::publish_quiet`]).
    pub fn publish_with_quiet(&mut self, fill: impl FnOnce(&mut T)) -> Result<u64, IpcError> {
        self.send_with(fill, false)
    }

    fn send_with(&mut self, fill: impl FnOnce(&mut T), wake: bool) -> Result<u64, IpcError> {
        let mut sample = self
            .port
            .loan()
            .map_err(|e| ipc_err("loan", &self.topic, e))?;
        let value = sample.payload_mut();
        fill(value);
        self.seq += 1;
        let h = value.header_mut();
        h.seq = self.seq;
        h.stamp_ns = monotonic_ns();
        h.service = self.service;
        h.instance = self.instance;
        sample.send().map_err(|e| ipc_err("send", &self.topic, e))?;
        self.sent(wake)
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }
}

/// Receives samples of one type from one topic.
pub struct Subscriber<T: Sample> {
    /// The topic's event, which the receives wait on.
    socket: SocketWait,
    port: iceoryx2::port::subscriber::Subscriber<Svc, T, ()>,
    counts: ReceiveCounts,
    topic: String,
    _bus: Bus,
}

impl<T: Sample> core::fmt::Debug for Subscriber<T> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Subscriber")
            .field("topic", &self.topic)
            .finish()
    }
}

impl<T: Sample> Subscriber<T> {
    /// Takes one pending sample without waiting.
    pub fn try_recv(&self) -> Result<Option<T>, IpcError> {
        let value = take(&self.port, &self.topic)?;
        if let Some(v) = &value {
            self.account(v);
        }
        Ok(value)
    }

    /// Takes one pending sample without waiting and hands it to `read` where it lies
    /// in shared memory (no copy: for large samples).
    pub fn try_recv_with<R>(&self, read: impl FnOnce(&T) -> R) -> Result<Option<R>, IpcError> {
        let Some(sample) = self
            .port
            .receive()
            .map_err(|e| ipc_err("receive", &self.topic, e))?
        else {
            return Ok(None);
        };
        self.account(sample.payload());
        Ok(Some(read(sample.payload())))
    }

    fn account(&self, value: &T) {
        let h = value.header();
        self.counts.count(h);
    }

    /// Declares that this subscriber wants only the newest value (it reads with
    /// [`Subscriber::latest`] at its own rate, slower than the publisher's), so
    /// samples overwritten in its buffer before it looked are by design and are not
    /// counted in `skymesh_topic_samples_lost_total`.
    pub fn set_newest_only(&mut self) {
        self.counts.newest_only = true;
    }

    /// Waits for the next sample. Cancel-safe: dropping the future loses nothing.
    /// A sample published quietly ([`Publisher::publish_quiet`]) is received with
    /// the next notified one (or by [`Subscriber::try_recv`]); a receive that found
    /// the queue empty waits for a notification without looking again.
    pub async fn recv(&mut self) -> Result<T, IpcError> {
        self.settle()?;
        loop {
            if let Some(v) = self.socket.notes.look(|| self.try_recv())? {
                return Ok(v);
            }
            self.wait_readable().await?;
        }
    }

    /// Waits for the next sample and hands it to `read` in place (see
    /// [`Subscriber::try_recv_with`]). Cancel-safe.
    pub async fn recv_with<R>(&mut self, mut read: impl FnMut(&T) -> R) -> Result<R, IpcError> {
        self.settle()?;
        loop {
            if let Some(r) = self.socket.notes.look(|| self.try_recv_with(&mut read))? {
                return Ok(r);
            }
            self.wait_readable().await?;
        }
    }

    /// Consumes the last wake-up's notification (see [`Notifications`]).
    fn settle(&self) -> Result<(), IpcError> {
        self.socket.settle_async(&self.topic)
    }

    /// Waits until the topic's event fires (a publisher notified).
    async fn wait_readable(&mut self) -> Result<(), IpcError> {
        self.socket.wait_async(&self.topic).await
    }

    /// Drains everything pending and returns the newest sample, if any.
    pub fn latest(&self) -> Result<Option<T>, IpcError> {
        let mut newest = None;
        while let Some(v) = self.try_recv()? {
            newest = Some(v);
        }
        Ok(newest)
    }

    /// Waits up to `timeout` for the next sample.
    pub async fn recv_timeout(&mut self, timeout: Duration) -> Result<Option<T>, IpcError> {
        match tokio::time::timeout(timeout, self.recv()).await {
            Ok(r) => r.map(Some),
            Err(_) => Ok(None),
        }
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sequence_table_keeps_each_publisher_apart_beyond_its_inline_slots() {
        let mut t = SeqTable::default();
        let n = SeqTable::INLINE as u16 + 3;
        for p in 0..n {
            assert_eq!(t.replace((p, 1), 10 + u64::from(p)), None, "publisher {p}");
        }
        for p in (0..n).rev() {
            let prev = t.replace((p, 1), 100 + u64::from(p));
            assert_eq!(prev, Some(10 + u64::from(p)), "publisher {p}");
        }
        assert_eq!(
            t.replace((0, 2), 5),
            None,
            "another instance is another publisher"
        );
        assert_eq!(t.replace((n - 1, 1), 7), Some(100 + u64::from(n - 1)));
    }

    #[test]
    fn shm_room_check_names_the_dir_and_the_numbers() {
        let dir = Path::new(SHM_DIR);
        let space = check_shm_room(dir, 0)
            .unwrap()
            .expect("/dev/shm is examinable");
        assert!(space.size >= space.free, "{space:?}");
        let e = check_shm_room(dir, u64::MAX).unwrap_err();
        assert_eq!(e.need, u64::MAX);
        let text = e.to_string();
        assert!(
            text.starts_with("shared memory /dev/shm is full: ")
                && text.contains(&format!("need at least {}", u64::MAX))
                && text.contains(SHM_MIN_FREE_ENV),
            "{text}"
        );
        // A directory that cannot be examined is left to iceoryx2.
        assert!(check_shm_room(Path::new("/nonexistent/skymesh"), u64::MAX)
            .unwrap()
            .is_none());
    }
}
