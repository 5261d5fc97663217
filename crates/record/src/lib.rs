//! skymesh-record: `skymesh record` and `skymesh replay`: bus topics to and from MCAP files.
//!
//! A recording holds one MCAP channel per topic (its name), each message one
//! sample as JSON (message encoding `json`), each channel's schema the sample
//! type's JSON schema (schema encoding `jsonschema`, named by the iceoryx2 type
//! name with its layout version, e.g. `skymesh.VehicleState.v2`), so Foxglove
//! Studio opens it and plots any field. Times: `log_time` is when the recorder
//! received the sample, `publish_time` when it was published (the header's
//! `CLOCK_MONOTONIC` stamp), both as Unix-epoch nanoseconds. The file is chunked,
//! uncompressed, indexed and finished when the recorder stops (SIGINT or SIGTERM).
//!
//! Topics are named exactly or by glob (`skymesh/vehicle/*/state`); globs are
//! resolved against the topics on the bus (iceoryx2's service listing) at the start
//! and every [`RESCAN`], so topics that appear later are recorded from then on.

pub mod json;
pub mod replay;
pub mod topics;

use std::collections::{BTreeMap, HashSet};
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::Context as _;
use skymesh_ipc_types::{ServiceId, Topic};
use skymesh_runtime::clock::monotonic_ns;
use skymesh_runtime::stats::Stats;
use skymesh_runtime::{Bus, Domain};
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use self::json::{with_kind, Recordable, MESSAGE_ENCODING, SCHEMA_ENCODING};
use self::topics::{Kind, Selection};

/// How often globs are resolved again against the bus's topics.
pub const RESCAN: Duration = Duration::from_secs(1);
/// Target size of an MCAP chunk (uncompressed): what a crash can lose.
pub const CHUNK_SIZE: u64 = 256 * 1024;

/// Nanoseconds to add to a `CLOCK_MONOTONIC` time for Unix-epoch time, measured now.
pub fn wall_offset_ns() -> i128 {
    let wall = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_nanos() as i128)
        .unwrap_or(0);
    wall - i128::from(monotonic_ns())
}

fn to_wall(mono_ns: u64, offset: i128) -> u64 {
    (i128::from(mono_ns) + offset).clamp(0, i128::from(u64::MAX)) as u64
}

/// One sample as JSON, on its way to the writer.
#[derive(Debug)]
pub struct Encoded {
    pub channel: u16,
    pub sequence: u32,
    pub log_time: u64,
    pub publish_time: u64,
    pub data: Vec<u8>,
}

/// What a recording wrote.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RecordSummary {
    pub topics: Vec<String>,
    pub messages: u64,
    pub bytes: u64,
}

/// An MCAP file being written: schemas and channels added as topics are found.
pub struct McapSink<W: Write + Seek> {
    writer: mcap::Writer<W>,
    schemas: BTreeMap<&'static str, u16>,
    topics: Vec<String>,
    messages: u64,
}

impl<W: Write + Seek> std::fmt::Debug for McapSink<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapSink")
            .field("topics", &self.topics)
            .field("messages", &self.messages)
            .finish()
    }
}

impl<W: Write + Seek> McapSink<W> {
    pub fn new(w: W) -> anyhow::Result<Self> {
        let writer = mcap::WriteOptions::new()
            .compression(None)
            .chunk_size(Some(CHUNK_SIZE))
            .library(concat!("skymesh record ", env!("CARGO_PKG_VERSION")))
            .create(w)
            .context("starting the MCAP file")?;
        Ok(McapSink {
            writer,
            schemas: BTreeMap::new(),
            topics: Vec::new(),
            messages: 0,
        })
    }

    /// Adds the channel of `topic` (and its type's schema, once); returns its id.
    pub fn add_channel(&mut self, kind: Kind, topic: &str) -> anyhow::Result<u16> {
        let name = kind.schema_name();
        let schema = match self.schemas.get(name) {
            Some(&id) => id,
            None => {
                let id = self
                    .writer
                    .add_schema(name, SCHEMA_ENCODING, &json::schema(kind))?;
                self.schemas.insert(name, id);
                id
            }
        };
        let metadata = BTreeMap::from([("type_name".to_string(), name.to_string())]);
        let id = self
            .writer
            .add_channel(schema, topic, MESSAGE_ENCODING, &metadata)?;
        self.topics.push(topic.to_string());
        Ok(id)
    }

    pub fn write(&mut self, m: &Encoded) -> anyhow::Result<()> {
        self.writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: m.channel,
                sequence: m.sequence,
                log_time: m.log_time,
                publish_time: m.publish_time,
            },
            &m.data,
        )?;
        self.messages += 1;
        Ok(())
    }

    /// Writes the summary and index and returns the underlying writer.
    pub fn finish(mut self) -> anyhow::Result<(RecordSummary, W)> {
        self.writer.finish().context("finishing the MCAP file")?;
        let summary = RecordSummary {
            topics: self.topics,
            messages: self.messages,
            bytes: 0,
        };
        Ok((summary, self.writer.into_inner()))
    }
}

/// One sample of type `T` as a message of `channel`.
pub fn encode<T: Recordable>(
    sample: &T,
    channel: u16,
    received_ns: u64,
    offset: i128,
) -> anyhow::Result<Encoded> {
    let h = sample.header();
    Ok(Encoded {
        channel,
        sequence: h.seq as u32,
        log_time: to_wall(received_ns, offset),
        publish_time: to_wall(h.stamp_ns, offset),
        data: serde_json::to_vec(sample)?,
    })
}

/// Receives every sample of `topic` and sends it as JSON until `stop`; then takes
/// what is still pending.
async fn follow<T: Recordable>(
    bus: Bus,
    topic: Topic,
    channel: u16,
    offset: i128,
    tx: mpsc::UnboundedSender<Encoded>,
    stop: CancellationToken,
) -> anyhow::Result<()> {
    let mut sub = bus
        .subscriber::<T>(&topic)
        .with_context(|| format!("subscribing to {}", topic.name))?;
    loop {
        let sample = tokio::select! {
            _ = stop.cancelled() => break,
            s = sub.recv() => s?,
        };
        if tx
            .send(encode(&sample, channel, monotonic_ns(), offset)?)
            .is_err()
        {
            return Ok(());
        }
    }
    while let Some(sample) = sub.try_recv()? {
        if tx
            .send(encode(&sample, channel, monotonic_ns(), offset)?)
            .is_err()
        {
            break;
        }
    }
    Ok(())
}

/// What `skymesh record` was asked for.
#[derive(Debug, Clone)]
pub struct RecordRequest {
    pub output: PathBuf,
    pub patterns: Vec<String>,
}

/// Records until `stop`, then finishes the file. Fails before creating the file if
/// a named topic is not supported.
pub async fn record(
    domain: &Domain,
    req: &RecordRequest,
    stop: CancellationToken,
) -> anyhow::Result<RecordSummary> {
    let selection = topics::select(&req.patterns)?;
    let bus = Bus::open(
        domain,
        &format!("skymesh-record-{}", std::process::id()),
        ServiceId::Tool,
        0,
        Stats::new(),
    )?;
    let file =
        File::create(&req.output).with_context(|| format!("creating {}", req.output.display()))?;
    let mut sink = McapSink::new(BufWriter::new(file))?;
    let offset = wall_offset_ns();
    let (tx, mut rx) = mpsc::unbounded_channel::<Encoded>();
    let tasks_stop = stop.child_token();
    let mut tasks = tokio::task::JoinSet::new();
    let mut recording: HashSet<String> = HashSet::new();
    let mut warned: HashSet<String> = HashSet::new();

    let mut start = |name: &str,
                     sink: &mut McapSink<BufWriter<File>>,
                     tasks: &mut tokio::task::JoinSet<anyhow::Result<()>>|
     -> anyhow::Result<()> {
        if recording.contains(name) {
            return Ok(());
        }
        let Some((kind, topic)) = topics::parse(name) else {
            return Ok(());
        };
        let channel = sink.add_channel(kind, name)?;
        let (bus, tx, stop) = (bus.clone(), tx.clone(), tasks_stop.clone());
        with_kind!(kind, T => {
            tasks.spawn(follow::<T>(bus, topic, channel, offset, tx, stop));
        });
        recording.insert(name.to_string());
        eprintln!("skymesh record: recording {name} ({})", kind.schema_name());
        Ok(())
    };

    for name in &selection.names {
        start(name, &mut sink, &mut tasks)?;
    }
    let mut rescan = tokio::time::interval(RESCAN);
    rescan.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = stop.cancelled() => break,
            Some(m) = rx.recv() => sink.write(&m)?,
            _ = rescan.tick(), if !selection.globs.is_empty() => {
                resolve(domain, &selection, &mut warned, |name| start(name, &mut sink, &mut tasks))?;
            }
            Some(done) = tasks.join_next() => {
                // One topic failing (its subscription refused) stops only that topic.
                if let Err(e) = done.context("a topic task panicked").and_then(|r| r) {
                    eprintln!("skymesh record: a topic stopped recording: {e:#}");
                }
            }
        }
    }
    drop(tx);
    // Every task takes what is pending and ends; then the channel closes.
    while let Some(done) = tasks.join_next().await {
        if let Err(e) = done.context("a topic task panicked").and_then(|r| r) {
            tracing::warn!(error = format!("{e:#}"), "a topic ended with an error");
        }
    }
    while let Some(m) = rx.recv().await {
        sink.write(&m)?;
    }
    let (mut summary, mut w) = sink.finish()?;
    w.flush()?;
    summary.bytes = w.get_ref().metadata().map(|m| m.len()).unwrap_or(0);
    w.get_ref().sync_all().ok();
    Ok(summary)
}

/// Starts every topic the globs match now; names the unsupported ones once.
fn resolve(
    domain: &Domain,
    selection: &Selection,
    warned: &mut HashSet<String>,
    mut start: impl FnMut(&str) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let existing = topics::list_bus_topics(domain)?;
    let (supported, refused) = selection.matches(&existing);
    for name in supported {
        start(name)?;
    }
    for name in refused {
        if warned.insert(name.to_string()) {
            eprintln!(
                "skymesh record: not recording {name}: its sample type has no JSON encoding (supported: {})",
                topics::FAMILIES.map(|f| f.template).join(", ")
            );
        }
    }
    Ok(())
}

/// Reads every message of a recording made by `skymesh record`: (topic, log time,
/// JSON) in file order. Refuses a file whose schemas this build does not know.
pub fn read_messages(path: &Path) -> anyhow::Result<Vec<(String, u64, serde_json::Value)>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    replay::check_channels(&bytes)?;
    let mut out = Vec::new();
    for m in mcap::MessageStream::new(&bytes)? {
        let m = m?;
        out.push((
            m.channel.topic.clone(),
            m.log_time,
            serde_json::from_slice(&m.data)?,
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::VehicleState;

    #[test]
    fn a_written_file_reads_back_with_schemas_and_times() {
        let mut sink = McapSink::new(std::io::Cursor::new(Vec::new())).unwrap();
        let ch = sink
            .add_channel(Kind::VehicleState, "skymesh/vehicle/1/state")
            .unwrap();
        let offset = wall_offset_ns();
        for i in 1..=3u64 {
            let mut s = VehicleState {
                alt_rel_m: i as f32,
                ..Default::default()
            };
            s.header.seq = i;
            s.header.stamp_ns = 1_000_000_000 * i;
            sink.write(&encode(&s, ch, 1_000_000_000 * i + 500, offset).unwrap())
                .unwrap();
        }
        let (summary, w) = sink.finish().unwrap();
        assert_eq!(summary.messages, 3);
        let bytes = w.into_inner();
        replay::check_channels(&bytes).unwrap();
        let s = mcap::Summary::read(&bytes).unwrap().unwrap();
        assert_eq!(s.stats.unwrap().message_count, 3);
        let ch = s.channels.values().next().unwrap();
        assert_eq!(ch.message_encoding, "json");
        let schema = ch.schema.as_ref().unwrap();
        assert_eq!(schema.name, "skymesh.VehicleState.v2");
        assert_eq!(schema.encoding, "jsonschema");
        let msgs: Vec<_> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(Result::unwrap)
            .collect();
        assert_eq!(msgs.len(), 3);
        assert_eq!(msgs[2].publish_time - msgs[0].publish_time, 2_000_000_000);
        assert_eq!(msgs[0].log_time - msgs[0].publish_time, 500);
        let v: serde_json::Value = serde_json::from_slice(&msgs[1].data).unwrap();
        assert_eq!(v["alt_rel_m"], 2.0);
        assert_eq!(msgs[1].sequence, 2);
    }
}
