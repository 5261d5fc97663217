//! The pose broadcast: every `broadcast_hz`, one UDP datagram holding every drone of
//! the latest `SwarmState` as an 84-byte GroundControl pose record, sent to each
//! configured destination (a subnet broadcast address in the field; the socket has
//! `SO_BROADCAST`).
//!
//! | pose field | from |
//! |---|---|
//! | id | `SwarmDrone::drone` |
//! | type | 0 (UAV) |
//! | liveness | config `liveness` (1 live, 2 simulated) |
//! | tracking x/y/z, orientation | `tracking`, `tracking_yaw_deg` |
//! | target x/y/z, orientation | `target`, `target_yaw_deg` |
//! | colour | `color` |
//! | timestamp | `SwarmState::time_s` |
//! | quaternion | `quaternion` |
//! | frameCount | the broadcast's own frame counter (one per datagram) |
//! | DroneState | `drone_state` |
//! | flags | `flags & 0x03` (idle, active; skymesh's other bits are masked off) |
//! | relativeRotation | `relative_rotation_deg` |
//!
//! No `SwarmState` yet, or none for `state_timeout_s` (the swarm queue stopped):
//! no datagram, counted as skipped; clients see the broadcast pause instead of
//! frozen poses that look live. While paused the task does not tick: it waits for
//! the queue's next `SwarmState` (the ticks it did not run are counted as skipped
//! when the broadcast resumes) and resumes at once.
//!
//! A destination nothing listens at (its host answers with ICMP port unreachable:
//! the default `127.0.0.1:6666` while no GroundControl runs) gets one datagram a
//! second instead of `broadcast_hz` until one draws no refusal
//! ([`skymesh_runtime::refusals`]); the others are counted as skipped
//! (`reason="not_listening"`). While every destination refuses the task does not
//! tick at all: it sleeps until the first probe is due (the ticks it skips are
//! counted the same way): a datagram to a closed loopback port costs the sender
//! tens of µs of CPU, at 30 Hz most of its idle cost. Broadcast addresses never
//! refuse.
//!
//! The task tells the swarm queue whether it reads the state (`SwarmWatch` on
//! `skymesh/swarm/watch`): watching while some destination may listen, renewed
//! every [`WATCH_RENEW`]; not watching while every destination refuses, so the
//! queue, when it has nothing to fly, ticks once a second instead of at its rate.
//! A probe watches again first and waits for the state the queue then publishes at
//! once (up to [`PROBE_STATE_WAIT`], or `state_timeout_s` if longer; the wait is
//! counted as skipped ticks, `reason="not_listening"`), so it never carries a
//! state from before it.
//!
//! Size: 84 bytes per drone, so 250 drones are 21 000 bytes in one datagram. That
//! is one datagram on loopback (MTU 64 KiB), but on Ethernet or Wi-Fi (MTU 1500)
//! the IP layer fragments it into 15 fragments, and losing any one loses the whole
//! frame; GroundControl does the same (one datagram per frame), and at 30 Hz a
//! lost frame is replaced 33 ms later. Above 779 drones a frame would exceed the
//! 65 507-byte UDP limit; the bus carries at most 256.

use std::net::SocketAddr;
use std::time::Duration;

use gc_proto::{encode_pose_datagram, PoseRecord, POSE_FLAGS_MASK, POSE_RECORD_LEN};
use skymesh_ipc_types::{SwarmDrone, SwarmState, SwarmWatch, SWARM_MAX_DRONES};
use skymesh_runtime::refusals::{self, Admit, Refusals};
use skymesh_runtime::timer::{instant_at, Ticker, Timer};
use skymesh_runtime::{IpcError, Publisher, Subscriber};
use tokio::net::UdpSocket;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use crate::drops::Drops;
use crate::metrics::BroadcastSkip;

/// GroundControl's object type of every skymesh drone: UAV.
pub const OBJECT_TYPE_UAV: u8 = 0;

/// The largest datagram the broadcast builds.
pub const MAX_DATAGRAM: usize = SWARM_MAX_DRONES * POSE_RECORD_LEN;

/// One drone's pose record.
pub fn pose_of(drone: &SwarmDrone, liveness: u8, time_s: f64, frame_count: u32) -> PoseRecord {
    PoseRecord {
        id: drone.drone,
        object_type: OBJECT_TYPE_UAV,
        liveness,
        tracking: drone.tracking,
        tracking_yaw_deg: drone.tracking_yaw_deg,
        target: drone.target,
        target_yaw_deg: drone.target_yaw_deg,
        color: drone.color,
        timestamp: time_s as f32,
        quaternion: drone.quaternion,
        frame_count,
        drone_state: i32::from(drone.drone_state),
        flags: drone.flags & POSE_FLAGS_MASK,
        relative_rotation_deg: drone.relative_rotation_deg,
    }
}

/// Replaces `buf` with the datagram of `state` (allocation-free once `buf` has
/// [`MAX_DATAGRAM`] capacity).
pub fn build_datagram(state: &SwarmState, liveness: u8, frame_count: u32, buf: &mut Vec<u8>) {
    let drones = state.drones();
    buf.clear();
    buf.resize(drones.len() * POSE_RECORD_LEN, 0);
    for (out, d) in buf.chunks_exact_mut(POSE_RECORD_LEN).zip(drones) {
        let out: &mut [u8; POSE_RECORD_LEN] = out.try_into().expect("chunks_exact: whole records");
        pose_of(d, liveness, state.time_s, frame_count).encode_into(out);
    }
}

/// Same bytes as [`build_datagram`] through `gc_proto::encode_pose_datagram` (for
/// the tests: the two must agree).
pub fn build_datagram_via_records(
    state: &SwarmState,
    liveness: u8,
    frame_count: u32,
    buf: &mut Vec<u8>,
) {
    let records: Vec<PoseRecord> = state
        .drones()
        .iter()
        .map(|d| pose_of(d, liveness, state.time_s, frame_count))
        .collect();
    encode_pose_datagram(&records, buf);
}

/// How long after a grid point the pose broadcast reads the `SwarmState`: the
/// swarm queue's tick (`tick_hz` on the same grid, 30 Hz by default like
/// `broadcast_hz`) publishes it within a millisecond when idle.
pub const QUEUE_TICK_ALLOWANCE: Duration = Duration::from_millis(2);

/// How often the broadcast renews its word that it watches the state (the queue
/// lets a word lapse after `SWARM_WATCH_LEASE_NS`, 3 s).
pub const WATCH_RENEW: Duration = Duration::from_secs(1);

/// How long a probe waits for the swarm queue's state after watching again, at
/// least (the queue ticks at once on the word; this only bounds a queue that does
/// not run).
pub const PROBE_STATE_WAIT: Duration = Duration::from_secs(2);

/// The broadcast's word on `skymesh/swarm/watch`: sent when it changes, and every
/// [`WATCH_RENEW`] while it watches.
struct Watch {
    publisher: Publisher<SwarmWatch>,
    watching: bool,
    said_at: Option<Instant>,
}

impl Watch {
    fn say(&mut self, watching: bool) -> Result<(), IpcError> {
        let now = Instant::now();
        let due = self
            .said_at
            .is_none_or(|t| now.duration_since(t) >= WATCH_RENEW);
        if watching != self.watching || (watching && due) {
            self.publisher.publish(SwarmWatch {
                watching: u8::from(watching),
                ..SwarmWatch::default()
            })?;
            self.watching = watching;
            self.said_at = Some(now);
        }
        Ok(())
    }
}

/// What the broadcast task needs.
#[derive(Debug)]
pub struct Broadcast {
    pub socket: UdpSocket,
    pub destinations: Vec<SocketAddr>,
    pub period: Duration,
    pub liveness: u8,
    pub state_timeout: Duration,
    pub drops: Drops,
}

impl Broadcast {
    /// Sends a datagram every period until `stop`. Fails only when the bus does.
    pub async fn run(
        self,
        mut state: Subscriber<SwarmState>,
        watch: Publisher<SwarmWatch>,
        stop: CancellationToken,
    ) -> Result<(), IpcError> {
        let mut watch = Watch {
            publisher: watch,
            watching: false,
            said_at: None,
        };
        // Every destination refusing: the ticks until the next probe are skipped.
        let mut asleep = false;
        let metrics = self.drops.metrics().clone();
        let mut latest: Box<SwarmState> = Box::default();
        let mut received_at: Option<Instant> = None;
        let mut stale_logged = false;
        let mut frame_count: u32 = 0;
        let mut buf = Vec::with_capacity(MAX_DATAGRAM);
        // A timerfd, not tokio's wheel (which would add ~16 wake-ups a second to a
        // 30 Hz tick): see skymesh_runtime::timer.
        let timer_err = IpcError::timer("the pose broadcast timer");
        // On the machine-wide grid, a little after the swarm queue's tick at the
        // same rate (its `SwarmState` is then ~2 ms old when sent, not anything up
        // to a period as with two unrelated clocks).
        let phase = QUEUE_TICK_ALLOWANCE.min(self.period / 2);
        let mut tick = Ticker::with_phase(self.period, phase).map_err(timer_err)?;
        let mut probe_wait = Timer::new().map_err(timer_err)?;
        let mut refusals = Refusals::new("pose broadcast");
        let reports = self
            .socket
            .local_addr()
            .and_then(|local| refusals::enable_reports(&self.socket, local));
        if let Err(e) = reports {
            // Only costs the saving: every destination is sent everything.
            tracing::warn!(error = %e, "cannot enable ICMP error reports on the broadcast socket");
        }
        loop {
            tokio::select! {
                _ = stop.cancelled() => return Ok(()),
                t = tick.tick() => { t.map_err(timer_err)?; }
            }
            let probing = std::mem::take(&mut asleep);
            if probing {
                // The queue rested: the states it published meanwhile are up to a
                // second old. It ticks at once on the word; send what it publishes
                // then.
                while state.try_recv_with(|_| ())?.is_some() {}
            }
            watch.say(probing || refusals.all_refusing_until(&self.destinations).is_none())?;
            if probing {
                // On a timerfd: a pending tokio timer would cost wake-ups of its
                // own (see skymesh_runtime::timer).
                let waited = Instant::now();
                let give_up = waited + self.state_timeout.max(PROBE_STATE_WAIT);
                tokio::select! {
                    _ = stop.cancelled() => return Ok(()),
                    r = state.recv_with(|s| *latest = *s) => {
                        r?;
                        received_at = Some(Instant::now());
                    }
                    r = probe_wait.sleep_until(give_up) => r.map_err(timer_err)?,
                }
                metrics.broadcast_ticks_skipped(
                    BroadcastSkip::NotListening,
                    waited.elapsed(),
                    self.period,
                    self.destinations.len(),
                );
            }
            let now = Instant::now();
            // Drained in place (the sample is ~20 KiB; `latest()` would copy it
            // out of shared memory and again into `latest`).
            let mut fresh = false;
            while state.try_recv_with(|s| *latest = *s)?.is_some() {
                fresh = true;
            }
            if fresh {
                received_at = Some(now);
            }
            let skip = match received_at {
                None => Some(BroadcastSkip::NoState),
                Some(at) if now.duration_since(at) > self.state_timeout => {
                    Some(BroadcastSkip::Stale)
                }
                Some(_) => None,
            };
            if let Some(reason) = skip {
                metrics.broadcast_skipped(reason);
                if reason == BroadcastSkip::Stale && !std::mem::replace(&mut stale_logged, true) {
                    tracing::warn!(
                        timeout_s = self.state_timeout.as_secs_f64(),
                        "no SwarmState from the swarm queue: pose broadcast paused"
                    );
                }
                // Nothing to send until the queue publishes again: wait for its next
                // sample instead of waking every period to find none.
                let paused = Instant::now();
                tokio::select! {
                    _ = stop.cancelled() => return Ok(()),
                    r = state.recv_with(|s| *latest = *s) => r?,
                };
                // Keep the skip counter what a tick per period would have made it.
                metrics.broadcast_ticks_skipped(reason, paused.elapsed(), self.period, 1);
                received_at = Some(Instant::now());
                tick.reset_immediately();
                continue;
            }
            if std::mem::replace(&mut stale_logged, false) {
                tracing::info!("SwarmState flowing again: pose broadcast resumed");
            }
            build_datagram(&latest, self.liveness, frame_count, &mut buf);
            frame_count = frame_count.wrapping_add(1);
            metrics.broadcast_drones.set(latest.drones().len() as f64);
            for &dest in &self.destinations {
                if refusals.admit(&self.socket, dest) == Admit::Skip {
                    metrics.broadcast_skipped(BroadcastSkip::NotListening);
                    continue;
                }
                let mut sent = self.socket.send_to(&buf, dest).await;
                if let Err(e) = &sent {
                    // A send fails with the error an earlier datagram drew (this
                    // one was not sent): read it, and send again unless this
                    // destination is the one refusing.
                    if refusals.send_failed(&self.socket, dest, e) {
                        sent = self.socket.send_to(&buf, dest).await;
                    } else if refusals.is_refusing(dest) {
                        metrics.broadcast_skipped(BroadcastSkip::NotListening);
                        continue;
                    }
                }
                match sent {
                    Ok(n) => {
                        metrics.broadcast_datagrams.inc();
                        metrics.broadcast_bytes.add(n as u64);
                    }
                    Err(e) => {
                        metrics.broadcast_errors.inc();
                        if let Some(hidden) = self.drops.allow("broadcast_send") {
                            tracing::warn!(
                                destination = %dest,
                                bytes = buf.len(),
                                error = %e,
                                similar_since_last_warning = hidden,
                                "sending the pose datagram failed"
                            );
                        }
                    }
                }
            }
            // Nobody listens anywhere: nothing to send until the first probe is due,
            // and the queue need not tick for us meanwhile.
            if let Some(at_ns) = refusals.all_refusing_until(&self.destinations) {
                watch.say(false)?;
                asleep = true;
                let at = instant_at(at_ns);
                metrics.broadcast_ticks_skipped(
                    BroadcastSkip::NotListening,
                    at.saturating_duration_since(Instant::now()),
                    self.period,
                    self.destinations.len(),
                );
                tick.skip_to(at);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gc_proto::decode_pose_datagram;
    use skymesh_ipc_types::drone_flags;

    fn state(n: usize) -> Box<SwarmState> {
        let mut s: Box<SwarmState> = Box::default();
        s.count = n as u16;
        s.time_s = 12.5;
        for (i, d) in s.drones.iter_mut().take(n).enumerate() {
            let f = i as f32;
            *d = SwarmDrone {
                drone: 100 + i as u16,
                vehicle_id: i as u8 + 1,
                drone_state: 10,
                flags: drone_flags::IDLE | drone_flags::ACTIVE | drone_flags::POSE_VALID,
                tracking: [f, -f, 2.0],
                tracking_yaw_deg: 90.0,
                quaternion: [
                    0.0,
                    0.0,
                    std::f32::consts::FRAC_1_SQRT_2,
                    std::f32::consts::FRAC_1_SQRT_2,
                ],
                target: [f + 1.0, -f, 3.0],
                target_yaw_deg: 45.0,
                color: [1.0, 0.5, 0.0],
                relative_rotation_deg: 10.0,
                ..SwarmDrone::default()
            };
        }
        s
    }

    #[test]
    fn every_drone_becomes_one_record() {
        let s = state(3);
        let mut buf = Vec::new();
        build_datagram(&s, 2, 77, &mut buf);
        assert_eq!(buf.len(), 3 * POSE_RECORD_LEN);
        let poses = decode_pose_datagram(&buf).unwrap();
        assert_eq!(poses.len(), 3);
        let p = &poses[2];
        assert_eq!(p.id, 102);
        assert_eq!((p.object_type, p.liveness), (0, 2));
        assert_eq!(p.tracking, [2.0, -2.0, 2.0]);
        assert_eq!(p.target, [3.0, -2.0, 3.0]);
        assert_eq!((p.tracking_yaw_deg, p.target_yaw_deg), (90.0, 45.0));
        assert_eq!(p.timestamp, 12.5);
        assert_eq!(p.frame_count, 77);
        assert_eq!(p.drone_state, 10);
        assert_eq!(p.flags, 0x03, "skymesh's extra bits are masked off");
        assert_eq!(p.relative_rotation_deg, 10.0);
        let mut via = Vec::new();
        build_datagram_via_records(&s, 2, 77, &mut via);
        assert_eq!(via, buf);
    }

    #[test]
    fn no_allocation_once_the_buffer_is_sized() {
        let s = state(250);
        let mut buf = Vec::with_capacity(MAX_DATAGRAM);
        let ptr = buf.as_ptr();
        build_datagram(&s, 1, 0, &mut buf);
        assert_eq!(buf.len(), 21_000);
        assert_eq!(buf.as_ptr(), ptr);
        // The count is clamped: a sample from another process can claim anything.
        let mut s = state(3);
        s.count = u16::MAX;
        build_datagram(&s, 1, 0, &mut buf);
        assert_eq!(buf.len(), MAX_DATAGRAM);
    }
}
