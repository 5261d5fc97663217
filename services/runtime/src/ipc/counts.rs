//! A subscriber's per-topic series: samples received, lost (gaps in a publisher's
//! sequence) and their age.

use std::sync::Mutex;

use skymesh_ipc_types::SampleHeader;

use crate::clock::monotonic_ns;
use crate::stats::{Counter, Histogram, Stats, LATENCY_BOUNDS_S};

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

/// A subscriber's per-topic series and gap counting, for [`super::Subscriber`] and
/// [`crate::FrameSubscriber`].
pub(crate) struct ReceiveCounts {
    received: Counter,
    lost: Counter,
    age: Histogram,
    /// Last sequence seen per publisher, for gap counting. Behind a mutex so reads
    /// work through `&self` (`try_recv` takes `&self`); never contended in practice.
    last_seq: Mutex<SeqTable>,
    /// Overwritten samples are expected, not lost (see `set_newest_only`).
    pub(super) newest_only: bool,
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
}
