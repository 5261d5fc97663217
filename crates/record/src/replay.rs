//! `skymesh replay`: publishes a recording onto a mesh at its recorded pace (or
//! `rate` times faster), so gateways and engines can be exercised without a vehicle.
//!
//! Each sample is published on its topic (with the topic's QoS) by a publisher of
//! this process: the header gets this publisher's sequence, time and id, and every
//! other `CLOCK_MONOTONIC` stamp in the sample (`*_stamp_ns`, `*_since_ns`,
//! `*_mono_ns`) moves with it, so ages computed from them are what they were when
//! recorded. Pacing follows each message's `log_time`.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Context as _};
use skymesh_ipc_types::ServiceId;
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::stats::Stats;
use skymesh_runtime::{Bus, Domain, Publisher};
use tokio_util::sync::CancellationToken;

use super::json::{shift_stamps, with_kind, Recordable, MESSAGE_ENCODING, SCHEMA_ENCODING};
use super::topics::{self, Kind};

/// Checks every channel of an MCAP file: a supported topic, JSON messages, and a
/// JSON schema this build knows (name and layout version) for the topic's type.
/// Returns each channel's kind.
pub fn check_channels(bytes: &[u8]) -> anyhow::Result<HashMap<u16, Kind>> {
    let summary = mcap::Summary::read(bytes)
        .context("reading the MCAP summary")?
        .context("the MCAP file has no summary section (the recording was not finished)")?;
    let known = topics::FAMILIES.map(|f| f.schema_name).join(", ");
    let mut kinds = HashMap::new();
    for (id, ch) in &summary.channels {
        let Some(schema) = &ch.schema else {
            bail!(
                "channel {:?} has no schema; this build replays {known}",
                ch.topic
            );
        };
        if schema.encoding != SCHEMA_ENCODING || ch.message_encoding != MESSAGE_ENCODING {
            bail!(
                "channel {:?}: schema encoding {:?}, message encoding {:?}; replay reads {SCHEMA_ENCODING:?} schemas with {MESSAGE_ENCODING:?} messages",
                ch.topic,
                schema.encoding,
                ch.message_encoding
            );
        }
        let Some(kind) = Kind::from_schema_name(&schema.name) else {
            bail!(
                "channel {:?}: unknown schema {:?} (another sample type or layout version); this build replays {known}",
                ch.topic,
                schema.name
            );
        };
        match topics::parse(&ch.topic) {
            Some((k, _)) if k == kind => {}
            _ => bail!(
                "channel {:?} does not carry {} on this build (supported topics:\n{})",
                ch.topic,
                schema.name,
                topics::supported_list()
            ),
        }
        kinds.insert(*id, kind);
    }
    Ok(kinds)
}

/// A publisher for one channel's samples, fed JSON.
trait JsonPublisher: Send {
    /// Publishes one sample; `delta` ns moves its monotonic stamps. A message that
    /// does not decode as the channel's type is not published: `Ok(Err(why))`.
    fn publish(&mut self, data: &[u8], delta: i128) -> anyhow::Result<Result<(), String>>;
}

struct Typed<T: Recordable>(Publisher<T>);

impl<T: Recordable> JsonPublisher for Typed<T> {
    fn publish(&mut self, data: &[u8], delta: i128) -> anyhow::Result<Result<(), String>> {
        let decoded = serde_json::from_slice::<serde_json::Value>(data).and_then(|mut value| {
            shift_stamps(&mut value, delta);
            serde_json::from_value::<T>(value)
        });
        match decoded {
            Ok(sample) => {
                self.0.publish(sample)?;
                Ok(Ok(()))
            }
            Err(e) => Ok(Err(e.to_string())),
        }
    }
}

/// What `skymesh replay` was asked for.
#[derive(Debug, Clone)]
pub struct ReplayRequest {
    pub input: PathBuf,
    /// Speed-up: 1 the recorded pace, 2 twice as fast.
    pub rate: f64,
}

/// What a replay published.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReplaySummary {
    pub channels: usize,
    pub messages: u64,
    /// Messages that did not decode as their channel's type (not published).
    pub skipped: u64,
}

/// Publishes the recording until its end or `stop`.
pub async fn replay(
    domain: &Domain,
    req: &ReplayRequest,
    stop: CancellationToken,
) -> anyhow::Result<ReplaySummary> {
    if !(req.rate.is_finite() && req.rate > 0.0) {
        bail!("--rate must be a positive number, not {}", req.rate);
    }
    let bytes =
        std::fs::read(&req.input).with_context(|| format!("reading {}", req.input.display()))?;
    let kinds = check_channels(&bytes).with_context(|| format!("{}", req.input.display()))?;
    let bus = Bus::open(
        domain,
        &format!("skymesh-replay-{}", std::process::id()),
        ServiceId::Tool,
        0,
        Stats::new(),
    )?;
    let mut publishers: HashMap<u16, Box<dyn JsonPublisher>> = HashMap::new();
    let mut first: Option<(u64, tokio::time::Instant)> = None;
    let mut summary = ReplaySummary {
        channels: kinds.len(),
        messages: 0,
        skipped: 0,
    };
    for m in mcap::MessageStream::new(&bytes)? {
        let m = m.context("reading a message")?;
        let publisher = match publishers.entry(m.channel.id) {
            std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::hash_map::Entry::Vacant(e) => {
                let (kind, topic) = topics::parse(&m.channel.topic)
                    .with_context(|| format!("unsupported topic {:?}", m.channel.topic))?;
                let p: Box<dyn JsonPublisher> = with_kind!(kind, T => Box::new(Typed::<T>(
                    bus.publisher::<T>(&topic)
                        .with_context(|| format!("publishing on {}", topic.name))?,
                )));
                e.insert(p)
            }
        };
        let (t0, start) = *first.get_or_insert((m.log_time, tokio::time::Instant::now()));
        let due =
            start + Duration::from_secs_f64(m.log_time.saturating_sub(t0) as f64 / 1e9 / req.rate);
        tokio::select! {
            _ = stop.cancelled() => break,
            _ = tokio::time::sleep_until(due) => {}
        }
        // The sample's own publish stamp, in the recording machine's monotonic time.
        let recorded_stamp = serde_json::from_slice::<serde_json::Value>(&m.data)
            .ok()
            .and_then(|v| v["header"]["stamp_ns"].as_u64())
            .unwrap_or(0);
        let delta = i128::from(monotonic_ns()) - i128::from(recorded_stamp);
        let published = publisher
            .publish(&m.data, delta)
            .with_context(|| format!("replaying a message of {}", m.channel.topic))?;
        match published {
            Ok(()) => summary.messages += 1,
            Err(why) => {
                if summary.skipped == 0 {
                    eprintln!(
                        "skymesh replay: skipping a message of {} that does not decode ({why}); later ones are only counted",
                        m.channel.topic
                    );
                }
                summary.skipped += 1;
            }
        }
    }
    Ok(summary)
}
