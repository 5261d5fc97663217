//! Setpoint freshness: how old a setpoint may be, and when a setpoint stream has
//! stopped. Pure; times are `CLOCK_MONOTONIC` ns.
//!
//! A setpoint's maximum age is its own `max_age_ms` (capped), else the default for
//! its source, else the global default. A sample older than that on arrival is
//! refused `Stale`. Each fresh setpoint keeps the stream alive until its own stamp
//! plus its maximum age; if no fresh setpoint has come by then and the last one
//! asked for motion, the arbiter brakes. A stamp in the future (impossible on one
//! machine, so corrupt or hostile) counts as "now", so it cannot keep a stream alive.

use skymesh_ipc_types::CommandSource;

/// Maximum ages, ns.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FreshnessPolicy {
    pub default_ns: u64,
    /// The most a sample may ask for with `max_age_ms`.
    pub cap_ns: u64,
    /// Per-source defaults, indexed by the wire value of [`CommandSource`].
    pub by_source: [Option<u64>; CommandSource::ALL.len()],
}

impl FreshnessPolicy {
    /// The maximum age of a setpoint from `source` that asks for `requested_ms` (0 = default).
    pub fn max_age_ns(&self, source: CommandSource, requested_ms: u32) -> u64 {
        if requested_ms > 0 {
            return (u64::from(requested_ms) * 1_000_000).min(self.cap_ns);
        }
        self.by_source
            .get(usize::from(source.to_wire()))
            .copied()
            .flatten()
            .unwrap_or(self.default_ns)
    }
}

/// Whether a setpoint stamped `stamp_ns` is fresh at `now_ns`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Freshness {
    /// Fresh; it keeps its stream alive until `until_ns`.
    Fresh {
        until_ns: u64,
    },
    Stale {
        age_ns: u64,
        max_ns: u64,
    },
}

pub fn check(stamp_ns: u64, now_ns: u64, max_ns: u64) -> Freshness {
    let age_ns = now_ns.saturating_sub(stamp_ns);
    if age_ns > max_ns {
        Freshness::Stale { age_ns, max_ns }
    } else {
        Freshness::Fresh {
            until_ns: stamp_ns.min(now_ns).saturating_add(max_ns),
        }
    }
}

/// The setpoint stream currently driving the vehicle (only the flight holder can
/// have one).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stream {
    pub source: CommandSource,
    pub until_ns: u64,
    /// The last setpoint asked for motion (a stopped stream of zeros needs no brake).
    pub moving: bool,
}

/// Tracks the one live setpoint stream.
#[derive(Debug, Clone, Default)]
pub struct Streams {
    current: Option<Stream>,
}

impl Streams {
    pub fn current(&self) -> Option<Stream> {
        self.current
    }

    /// A fresh setpoint was let through.
    pub fn fed(&mut self, source: CommandSource, until_ns: u64, moving: bool) {
        self.current = Some(Stream {
            source,
            until_ns,
            moving,
        });
    }

    /// Something else now decides what the vehicle does (a position target, a
    /// brake, a mode change, ...): no stream to watch.
    pub fn end(&mut self) {
        self.current = None;
    }

    /// The stream whose deadline has passed and that must be braked, if any.
    pub fn poll(&mut self, now_ns: u64) -> Option<Stream> {
        let s = self.current?;
        if now_ns < s.until_ns {
            return None;
        }
        self.current = None;
        s.moving.then_some(s)
    }

    pub fn deadline(&self) -> Option<u64> {
        self.current.map(|s| s.until_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn policy() -> FreshnessPolicy {
        let mut by_source = [None; CommandSource::ALL.len()];
        by_source[usize::from(CommandSource::Vision.to_wire())] = Some(200 * MS);
        FreshnessPolicy {
            default_ns: 500 * MS,
            cap_ns: 2000 * MS,
            by_source,
        }
    }

    #[test]
    fn max_age_comes_from_the_sample_the_source_or_the_default() {
        let p = policy();
        assert_eq!(p.max_age_ns(CommandSource::Operator, 0), 500 * MS);
        assert_eq!(p.max_age_ns(CommandSource::Vision, 0), 200 * MS);
        assert_eq!(p.max_age_ns(CommandSource::Vision, 300), 300 * MS);
        assert_eq!(
            p.max_age_ns(CommandSource::Imc, 60_000),
            2000 * MS,
            "capped"
        );
    }

    #[test]
    fn stale_on_arrival_and_future_stamps_cannot_extend_a_stream() {
        assert_eq!(
            check(1000 * MS, 1600 * MS, 500 * MS),
            Freshness::Stale {
                age_ns: 600 * MS,
                max_ns: 500 * MS
            }
        );
        assert_eq!(
            check(1000 * MS, 1400 * MS, 500 * MS),
            Freshness::Fresh {
                until_ns: 1500 * MS
            }
        );
        assert_eq!(
            check(u64::MAX - 5, 1000 * MS, 500 * MS),
            Freshness::Fresh {
                until_ns: 1500 * MS
            },
            "a stamp from the future counts as now"
        );
    }

    #[test]
    fn a_stopped_moving_stream_is_braked_once() {
        let mut s = Streams::default();
        s.fed(CommandSource::ShotEngine, 500 * MS, true);
        s.fed(CommandSource::ShotEngine, 600 * MS, true);
        assert_eq!(s.deadline(), Some(600 * MS));
        assert_eq!(s.poll(599 * MS), None);
        assert_eq!(
            s.poll(600 * MS).map(|x| x.source),
            Some(CommandSource::ShotEngine)
        );
        assert_eq!(s.poll(700 * MS), None);
        assert_eq!(s.deadline(), None);
        s.fed(CommandSource::ShotEngine, 800 * MS, false);
        assert_eq!(s.poll(900 * MS), None, "zero velocity needs no brake");
        assert_eq!(s.deadline(), None);
        s.fed(CommandSource::ShotEngine, 800 * MS, true);
        s.end();
        assert_eq!(s.deadline(), None);
    }
}
