//! The futex wake-up for blocking receivers ([`crate::Subscriber::set_futex_wake`]).
//!
//! Every topic has two iceoryx2 event services, and every publisher notifies both:
//!
//! - the **socket** event (iceoryx2's default: a Unix datagram per wake-up). It has a
//!   file descriptor, so tokio and epoll can wait on it: every async receiver uses it.
//!   A blocking wait on it is two system calls (the wait and the read that re-arms
//!   the notifier), against one `recv` for a UDP socket: on this project's VM the
//!   mechanism alone costs the receiver 1.3× UDP's CPU per message
//!   (`scripts/wake-floor.c`).
//! - the **futex** event (iceoryx2's semaphore event, a process-shared POSIX
//!   semaphore in shared memory): the waiter sleeps in one `futex` call, the notifier
//!   wakes it with one, and re-arming is a user-space decrement. It has no file
//!   descriptor, so only a thread that blocks can use it.
//!
//! A notify with nobody listening on an event is a few atomic loads (no system
//! call), so the second event costs publishers nothing until a blocking receiver
//! asks for it.
//!
//! The futex services live under their own file prefix (`<domain>.fx_`, see
//! [`crate::Domain::wake_config`]): their shared-memory layout differs from the socket
//! event's, and the two service kinds must never open each other's files.
//!
//! **Timeouts.** iceoryx2's timed wait on a semaphore polls (10,000 `sched_yield`s,
//! then sleeps of 100 µs and 10 ms), so a timed futex wait here is an untimed
//! `sem_wait` plus a *watchdog*: one thread per subscriber, started by its first
//! timed wait, that sleeps until the waiting receive's deadline and, if the receive
//! is still waiting then, notifies the topic's futex event. The receive publishes its
//! deadline in an atomic (no system call); the watchdog wakes at most once per
//! deadline, and is woken early only when a deadline comes before the one it sleeps
//! towards (a shorter timeout than the last, or any while it sleeps with nothing to
//! watch: then it never wakes by itself). Its notify wakes every futex receiver
//! of the topic, in every process: those find no sample and wait again. That happens
//! only when a timeout expires, i.e. when the topic has gone quiet.

use core::fmt::Debug;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::ZeroCopySend;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator;
use iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator;
use iceoryx2_cal::{
    arc_sync_policy, bag, dynamic_storage, event, hash, monitoring, reactor,
    resizable_shared_memory, serialize, shared_memory, static_storage, zero_copy_connection,
};

use crate::clock::monotonic_ns;
use crate::ipc::{ipc_err, IpcError};

/// `ipc_threadsafe::Service` with iceoryx2's semaphore event in place of its socket
/// event: the iceoryx2 service flavour of the futex wake-up. Only its event services
/// are used.
#[derive(Debug, Clone)]
pub struct WakeSvc {}

impl iceoryx2::service::Service for WakeSvc {
    type StaticStorage = static_storage::recommended::Ipc;
    type ConfigSerializer = serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::PersistentIpc<T>;
    type Bag = bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<T>;
    type ServiceNameHasher = hash::recommended::Recommended;
    type SharedMemory = shared_memory::recommended::Ipc<PoolAllocator>;
    type ResizableSharedMemory = resizable_shared_memory::recommended::Ipc<PoolAllocator>;
    type Connection = zero_copy_connection::recommended::Ipc;
    type Event = event::SemaphoreShmCountingBitSet;
    type Monitoring = monitoring::recommended::Ipc;
    type Reactor = reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> =
        arc_sync_policy::mutex_protected::MutexProtected<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        dynamic_storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = shared_memory::recommended::Ipc<BumpAllocator>;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<WakeSvc> for WakeSvc {}

/// The event service port factory of a topic's futex event.
pub(crate) type WakeEvent = iceoryx2::service::port_factory::event::PortFactory<WakeSvc>;

/// The `CLOCK_MONOTONIC` deadline (ns) of a receive with `timeout`, for
/// [`FutexWait::wait`]: computed once per receive, not per wait.
pub(crate) fn deadline_ns(timeout: Option<Duration>) -> Option<u64> {
    timeout.map(|t| monotonic_ns().saturating_add(u64::try_from(t.as_nanos()).unwrap_or(u64::MAX)))
}

/// `deadline_ns` when no receive is waiting.
const NOT_WAITING: u64 = 0;

/// What a receive and its watchdog share.
#[derive(Debug)]
struct Watch {
    /// `CLOCK_MONOTONIC` ns at which the waiting receive times out; [`NOT_WAITING`].
    deadline_ns: AtomicU64,
    /// When the watchdog will next look by itself (ns), so a receive with an earlier
    /// deadline knows to wake it.
    looks_at_ns: AtomicU64,
    stop: AtomicBool,
}

#[derive(Debug)]
struct Watchdog {
    watch: Arc<Watch>,
    thread: JoinHandle<()>,
}

/// A subscriber's futex listener, and the watchdog behind its timeouts.
#[derive(Debug)]
pub(crate) struct FutexWait {
    listener: Listener<WakeSvc>,
    event: WakeEvent,
    watchdog: std::sync::OnceLock<Watchdog>,
    topic: String,
}

impl FutexWait {
    pub(crate) fn new(event: WakeEvent, topic: &str) -> Result<FutexWait, IpcError> {
        let listener = event
            .listener_builder()
            .create()
            .map_err(|e| ipc_err("create futex listener", topic, e))?;
        Ok(FutexWait {
            listener,
            event,
            watchdog: std::sync::OnceLock::new(),
            topic: topic.to_string(),
        })
    }

    /// Consumes notifications already pending (user space: semaphore decrements),
    /// so the next wait blocks until a new one.
    pub(crate) fn drain(&self) -> Result<(), IpcError> {
        self.listener
            .try_wait(|_| {})
            .map_err(|e| ipc_err("futex listener wait", &self.topic, e))?;
        Ok(())
    }

    /// Blocks until the topic's futex event is notified (a sample was published,
    /// a notification was pending, or this receive's watchdog fired at
    /// `deadline_ns`, see [`deadline_ns`]; `None` waits indefinitely), or a signal
    /// arrives. Callers look for samples and at the clock whichever it was.
    pub(crate) fn wait(&self, deadline_ns: Option<u64>) -> Result<(), IpcError> {
        let watch = match deadline_ns {
            Some(d) => {
                let dog = self.watchdog()?;
                dog.watch.deadline_ns.store(d.max(1), Ordering::SeqCst);
                if d < dog.watch.looks_at_ns.load(Ordering::SeqCst) {
                    dog.thread.thread().unpark();
                }
                Some(&dog.watch)
            }
            None => None,
        };
        let res = self.listener.blocking_wait(|_| {});
        if let Some(w) = watch {
            w.deadline_ns.store(NOT_WAITING, Ordering::SeqCst);
        }
        match res {
            Ok(_) => Ok(()),
            // A signal: the caller looks and waits again, as after a socket wait.
            Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => Ok(()),
            Err(e) => Err(ipc_err("futex listener wait", &self.topic, e)),
        }
    }

    fn watchdog(&self) -> Result<&Watchdog, IpcError> {
        match self.watchdog.get() {
            Some(w) => Ok(w),
            None => self.start_watchdog(),
        }
    }

    /// The first timed wait's: out of line, so that every later wait (the one that
    /// wakes after a long sleep) does not carry a thread start's code and stack.
    #[cold]
    #[inline(never)]
    fn start_watchdog(&self) -> Result<&Watchdog, IpcError> {
        let notifier = self
            .event
            .notifier_builder()
            .create()
            .map_err(|e| ipc_err("create futex watchdog notifier", &self.topic, e))?;
        let watch = Arc::new(Watch {
            deadline_ns: AtomicU64::new(NOT_WAITING),
            looks_at_ns: AtomicU64::new(0),
            stop: AtomicBool::new(false),
        });
        let w = Arc::clone(&watch);
        let topic = self.topic.clone();
        let thread = std::thread::Builder::new()
            .name("futex-watchdog".into())
            .spawn(move || watchdog_loop(&w, &notifier, &topic))
            .map_err(|e| ipc_err("start futex watchdog", &self.topic, e))?;
        // Only the subscriber's own receives get here, one at a time in practice; a
        // racing second watchdog would stop at once when dropped below.
        match self.watchdog.set(Watchdog { watch, thread }) {
            Ok(()) => {}
            Err(extra) => stop(extra),
        }
        Ok(self.watchdog.get().expect("set above"))
    }
}

impl Drop for FutexWait {
    fn drop(&mut self) {
        if let Some(dog) = self.watchdog.take() {
            stop(dog);
        }
    }
}

fn stop(dog: Watchdog) {
    dog.watch.stop.store(true, Ordering::SeqCst);
    dog.thread.thread().unpark();
    let _ = dog.thread.join();
}

/// `looks_at_ns` while no receive is waiting: the watchdog sleeps until the next
/// timed wait wakes it (any deadline is earlier).
const NEVER: u64 = u64::MAX;

fn watchdog_loop(watch: &Watch, notifier: &Notifier<WakeSvc>, topic: &str) {
    // The deadline this watchdog has already fired for: a receive that is slow to
    // clear it after its wake-up is not notified twice.
    let mut fired = NOT_WAITING;
    while !watch.stop.load(Ordering::SeqCst) {
        let now = monotonic_ns();
        let deadline = watch.deadline_ns.load(Ordering::SeqCst);
        let look_at = if deadline == NOT_WAITING || deadline == fired {
            NEVER
        } else if now >= deadline {
            if let Err(e) = notifier.notify() {
                tracing::warn!(topic, error = ?e, "futex watchdog could not wake a timed-out receive");
            }
            fired = deadline;
            continue;
        } else {
            deadline
        };
        watch.looks_at_ns.store(look_at, Ordering::SeqCst);
        // A deadline set after the load above and before this store, earlier than
        // `look_at`, unparks this thread (the receive reads `looks_at_ns` after it
        // stores its deadline): the park below then returns at once.
        let now = monotonic_ns();
        if watch.deadline_ns.load(Ordering::SeqCst) != deadline {
            continue;
        }
        if look_at == NEVER {
            std::thread::park();
        } else if look_at > now {
            std::thread::park_timeout(Duration::from_nanos(look_at - now));
        }
    }
}
