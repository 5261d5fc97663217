//! How a receive waits on its topic's event: the listener registered with tokio's
//! reactor, and what the receives know about its notifications.

use std::os::fd::{AsRawFd, BorrowedFd, RawFd};
use std::sync::atomic::{AtomicBool, Ordering};

use iceoryx2::port::listener::Listener;
use iceoryx2::prelude::FileDescriptorBased;
use tokio::io::unix::AsyncFd;

use super::{ipc_err, IpcError, Svc};

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
    pub(super) fn look<R>(
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
