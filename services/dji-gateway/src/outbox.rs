//! What goes to the cloud: a bounded queue that holds messages while the broker is
//! unreachable (oldest dropped first when full), and the events sent with
//! `need_reply: 1`, re-sent every [`RESEND_EVERY`] until the cloud answers on
//! `events_reply` (same tid and bid), at most [`MAX_RESENDS`] times. Pure, explicit
//! time; the MQTT loop drains it while connected.

use std::collections::{HashMap, VecDeque};
use std::time::{Duration, Instant};

use dji_proto::TopicKind;

/// An unanswered `need_reply` event is sent again after this long.
pub const RESEND_EVERY: Duration = Duration::from_secs(2);
/// Re-sends of one event before the gateway gives up on its reply.
pub const MAX_RESENDS: u32 = 5;
/// Events awaiting a reply; beyond this the oldest is forgotten (not re-sent).
pub const MAX_AWAITING: usize = 256;

/// One outbound MQTT message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OutMessage {
    /// `ServicesReply` or `Events`.
    pub topic: TopicKind,
    /// For metrics: one of the document's method names.
    pub method: &'static str,
    pub payload: Vec<u8>,
}

#[derive(Debug, Clone)]
struct Awaiting {
    message: OutMessage,
    /// When it was first sent (for ordering evictions).
    first: Instant,
    next_at: Instant,
    resends: u32,
}

/// What [`Outbox::resend_due`] did.
#[derive(Debug, Default, PartialEq, Eq)]
pub struct ResendRound {
    /// Methods re-sent now.
    pub resent: Vec<&'static str>,
    /// Methods whose reply never came (given up).
    pub gave_up: Vec<&'static str>,
}

#[derive(Debug)]
pub struct Outbox {
    queue: VecDeque<OutMessage>,
    capacity: usize,
    awaiting: HashMap<(String, String), Awaiting>,
}

impl Outbox {
    pub fn new(capacity: usize) -> Self {
        Outbox {
            queue: VecDeque::new(),
            capacity: capacity.max(1),
            awaiting: HashMap::new(),
        }
    }

    /// Queues `m`; returns the message dropped to make room, if the queue was full.
    pub fn push(&mut self, m: OutMessage) -> Option<OutMessage> {
        let dropped = if self.queue.len() >= self.capacity {
            self.queue.pop_front()
        } else {
            None
        };
        self.queue.push_back(m);
        dropped
    }

    /// The next message to publish.
    pub fn pop(&mut self) -> Option<OutMessage> {
        self.queue.pop_front()
    }

    /// Puts back a message the client could not take (it goes out first next time).
    pub fn unpop(&mut self, m: OutMessage) {
        self.queue.push_front(m);
        if self.queue.len() > self.capacity {
            self.queue.pop_back();
        }
    }

    pub fn queued(&self) -> usize {
        self.queue.len()
    }

    /// Queues an event sent with `need_reply: 1` and remembers it for re-sending.
    /// Returns the message dropped from the queue, if any.
    pub fn push_awaiting_reply(
        &mut self,
        tid: &str,
        bid: &str,
        m: OutMessage,
        now: Instant,
    ) -> Option<OutMessage> {
        if self.awaiting.len() >= MAX_AWAITING {
            if let Some(oldest) = self
                .awaiting
                .iter()
                .min_by_key(|(_, a)| a.first)
                .map(|(k, _)| k.clone())
            {
                self.awaiting.remove(&oldest);
            }
        }
        self.awaiting.insert(
            (tid.to_string(), bid.to_string()),
            Awaiting {
                message: m.clone(),
                first: now,
                next_at: now + RESEND_EVERY,
                resends: 0,
            },
        );
        self.push(m)
    }

    /// The cloud answered the event `tid`/`bid`: its method, if it was awaited.
    pub fn on_reply(&mut self, tid: &str, bid: &str) -> Option<&'static str> {
        self.awaiting
            .remove(&(tid.to_string(), bid.to_string()))
            .map(|a| a.message.method)
    }

    pub fn awaiting(&self) -> usize {
        self.awaiting.len()
    }

    /// When the first awaited event is due for a re-send (what
    /// [`Outbox::resend_due`] acts on); `None` when nothing awaits a reply.
    pub fn next_resend(&self) -> Option<Instant> {
        self.awaiting.values().map(|a| a.next_at).min()
    }

    /// Re-queues every awaited event that is due (call only while connected: time
    /// offline does not use up the re-sends).
    pub fn resend_due(&mut self, now: Instant) -> ResendRound {
        let mut round = ResendRound::default();
        let mut due: Vec<(Instant, (String, String))> = self
            .awaiting
            .iter()
            .filter(|(_, a)| now >= a.next_at)
            .map(|(k, a)| (a.first, k.clone()))
            .collect();
        due.sort();
        for (_, key) in due {
            let Some(a) = self.awaiting.get_mut(&key) else {
                continue;
            };
            if a.resends >= MAX_RESENDS {
                round.gave_up.push(a.message.method);
                self.awaiting.remove(&key);
                continue;
            }
            a.resends += 1;
            a.next_at = now + RESEND_EVERY;
            let m = a.message.clone();
            round.resent.push(m.method);
            self.push(m);
        }
        round
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(method: &'static str, n: u8) -> OutMessage {
        OutMessage {
            topic: TopicKind::Events,
            method,
            payload: vec![n],
        }
    }

    #[test]
    fn the_queue_is_bounded_and_drops_the_oldest() {
        let mut o = Outbox::new(2);
        assert_eq!(o.push(msg("a", 1)), None);
        assert_eq!(o.push(msg("b", 2)), None);
        assert_eq!(o.push(msg("c", 3)), Some(msg("a", 1)));
        assert_eq!(o.pop(), Some(msg("b", 2)));
        o.unpop(msg("b", 2));
        assert_eq!(o.queued(), 2);
        assert_eq!(o.pop(), Some(msg("b", 2)));
        assert_eq!(o.pop(), Some(msg("c", 3)));
        assert_eq!(o.pop(), None);
    }

    #[test]
    fn awaited_events_are_resent_until_answered_then_given_up() {
        let t0 = Instant::now();
        let mut o = Outbox::new(100);
        o.push_awaiting_reply("t1", "b1", msg("fly_to_point_progress", 1), t0);
        o.push_awaiting_reply("t2", "b2", msg("poi_status_notify", 2), t0);
        assert_eq!(o.queued(), 2);
        while o.pop().is_some() {}
        assert_eq!(
            o.resend_due(t0 + Duration::from_secs(1)),
            ResendRound::default()
        );
        let r = o.resend_due(t0 + RESEND_EVERY);
        assert_eq!(r.resent.len(), 2);
        assert_eq!(o.queued(), 2);
        while o.pop().is_some() {}
        // An answer with the wrong bid does not count.
        assert_eq!(o.on_reply("t1", "bX"), None);
        assert_eq!(o.on_reply("t1", "b1"), Some("fly_to_point_progress"));
        assert_eq!(o.on_reply("t1", "b1"), None, "answered once");
        let mut t = t0 + RESEND_EVERY;
        let mut resent = 1;
        loop {
            t += RESEND_EVERY;
            let r = o.resend_due(t);
            if !r.gave_up.is_empty() {
                assert_eq!(r.gave_up, vec!["poi_status_notify"]);
                break;
            }
            assert_eq!(r.resent, vec!["poi_status_notify"]);
            resent += 1;
        }
        assert_eq!(resent, MAX_RESENDS);
        assert_eq!(o.awaiting(), 0);
    }

    #[test]
    fn the_awaiting_table_is_bounded() {
        let t0 = Instant::now();
        let mut o = Outbox::new(10);
        for i in 0..MAX_AWAITING + 3 {
            let at = t0 + Duration::from_millis(i as u64);
            o.push_awaiting_reply(&format!("t{i}"), "b", msg("e", 0), at);
        }
        assert_eq!(o.awaiting(), MAX_AWAITING);
        assert_eq!(o.on_reply("t0", "b"), None, "oldest forgotten");
        assert_eq!(
            o.on_reply(&format!("t{}", MAX_AWAITING + 2), "b"),
            Some("e")
        );
        assert_eq!(o.queued(), 10);
    }
}
