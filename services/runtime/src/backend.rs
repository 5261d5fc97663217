//! Waiting for a gateway's backend: a request the backend answers, sent while no
//! backend reads the bus, waits a bounded time for one to appear before the gateway
//! answers it with its protocol's error (issue 43: ready means able to serve).

use std::time::Duration;

use tokio::time::Instant;

/// While no backend reads the bus, how often a waiting request looks again.
const POLL: Duration = Duration::from_millis(10);

/// Whether a gateway's backend is there, per client connection.
#[derive(Debug, Default)]
pub struct BackendWait {
    /// A wait ran out and no backend appeared since: the next request is answered
    /// at once instead of waiting again (a burst of requests would otherwise each
    /// hold the connection for the whole wait).
    gone: bool,
}

impl BackendWait {
    /// Whether `reads()` (a backend subscribes to the request's topic) holds now
    /// or within `wait`; after a wait that ran out, only now, until it holds again.
    pub async fn present(&mut self, wait: Duration, reads: impl Fn() -> bool) -> bool {
        if reads() {
            self.gone = false;
            return true;
        }
        if self.gone {
            return false;
        }
        let deadline = Instant::now() + wait;
        while Instant::now() < deadline {
            tokio::time::sleep(POLL.min(deadline - Instant::now())).await;
            if reads() {
                return true;
            }
        }
        self.gone = true;
        false
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicBool, Ordering};

    use super::*;

    #[tokio::test(start_paused = true)]
    async fn waits_once_then_answers_at_once_until_the_backend_is_back() {
        let up = AtomicBool::new(false);
        let mut b = BackendWait::default();
        let wait = Duration::from_secs(2);
        let t = Instant::now();
        assert!(!b.present(wait, || up.load(Ordering::Relaxed)).await);
        assert!(t.elapsed() >= wait, "waited {:?}", t.elapsed());
        let t = Instant::now();
        assert!(!b.present(wait, || up.load(Ordering::Relaxed)).await);
        assert_eq!(t.elapsed(), Duration::ZERO, "gone: answered at once");
        up.store(true, Ordering::Relaxed);
        assert!(b.present(wait, || up.load(Ordering::Relaxed)).await);
        up.store(false, Ordering::Relaxed);
        let t = Instant::now();
        assert!(!b.present(wait, || up.load(Ordering::Relaxed)).await);
        assert!(t.elapsed() >= wait, "back and gone again: waits again");
    }

    #[tokio::test(start_paused = true)]
    async fn a_backend_appearing_within_the_wait_is_found() {
        let mut b = BackendWait::default();
        let t = Instant::now();
        let found = b
            .present(Duration::from_secs(2), || {
                t.elapsed() >= Duration::from_millis(300)
            })
            .await;
        assert!(found);
        assert!(
            t.elapsed() < Duration::from_millis(400),
            "{:?}",
            t.elapsed()
        );
    }
}
