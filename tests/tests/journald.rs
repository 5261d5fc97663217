//! Logs to journald (services/runtime/src/logging.rs), through a real
//! systemd-journald: the test starts one in a private mount namespace (a tmpfs over
//! `/run`, so the host's `/run` and any journal it has are untouched), runs a
//! service with `JOURNAL_STREAM` naming its stderr, as systemd sets it, and reads the
//! entries back with `journalctl -o json`.
//!
//! Needs root, `unshare`, `systemd-journald` and `journalctl` (Debian's `systemd`);
//! without them it prints `journald not available: <why>` and runs only the part
//! that needs none: with no journald socket, `auto` under a journal stream falls
//! back to text on stderr and says why.

use std::os::unix::fs::MetadataExt as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use skymesh_e2e::binary;

const JOURNALD: [&str; 2] = [
    "/lib/systemd/systemd-journald",
    "/usr/lib/systemd/systemd-journald",
];
const HOST_SOCKET: &str = "/run/systemd/journal/socket";

/// A broker config that fails validation: `--check-config` logs one ERROR event
/// (`bad configuration`, field `error`) and exits 64.
const BAD_CONFIG: &str = "listen = \"not an address\"\n";

fn journald_binary() -> Option<&'static str> {
    JOURNALD.into_iter().find(|p| Path::new(p).exists())
}

fn found(program: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {program}")])
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Why the real-journald part cannot run here, if it cannot.
fn unavailable() -> Option<String> {
    // /proc/self belongs to the process's effective user.
    let uid = std::fs::metadata("/proc/self")
        .map(|m| m.uid())
        .unwrap_or(u32::MAX);
    if uid != 0 {
        return Some("not root (a private mount namespace needs it)".into());
    }
    for program in ["unshare", "journalctl", "stat"] {
        if !found(program) {
            return Some(format!("`{program}` not found"));
        }
    }
    if journald_binary().is_none() {
        return Some(format!("none of {JOURNALD:?}"));
    }
    let probe = Command::new("unshare")
        .args(["-m", "sh", "-c", "mount -t tmpfs tmpfs /run"])
        .output();
    match probe {
        Ok(o) if o.status.success() => None,
        Ok(o) => Some(format!(
            "cannot mount a tmpfs in a private mount namespace: {}",
            String::from_utf8_lossy(&o.stderr).trim()
        )),
        Err(e) => Some(format!("unshare: {e}")),
    }
}

/// What a run inside the namespace left: the journal entries of the broker (JSON
/// objects) and each case's stderr.
struct Journal {
    entries: Vec<serde_json::Value>,
    stderr_auto: String,
    stderr_json: String,
    stderr_redirected: String,
}

/// Starts journald in a private mount namespace and runs the broker three times
/// with `JOURNAL_STREAM` set: `auto` with stderr being that stream (→ journald),
/// `--log-format json` (→ JSON on stderr), and `auto` with stderr redirected to
/// another file (→ text on stderr). Waits until journalctl shows the first run's
/// entry (never a fixed sleep), then prints the broker's entries.
fn run_in_namespace(dir: &Path, broker: &Path, config: &Path) -> Result<Journal> {
    let journald = journald_binary().context("systemd-journald")?;
    let script = format!(
        r#"set -u
mount -t tmpfs tmpfs /run || exit 90
{journald} &
jd=$!
trap 'kill $jd 2>/dev/null; wait $jd 2>/dev/null' EXIT
n=0
until [ -S /run/systemd/journal/socket ]; do
  n=$((n + 1)); [ $n -gt 3000 ] && {{ echo "journald made no socket" >&2; exit 91; }}
  sleep 0.01
done
: > /run/stream
export JOURNAL_STREAM=$(stat -c %d:%i /run/stream)
"{broker}" --config "{config}" --check-config 2>>/run/stream
echo "exit auto $?" >&2
"{broker}" --log-format json --config "{config}" --check-config 2>"{dir}/json.err"
echo "exit json $?" >&2
"{broker}" --config "{config}" --check-config 2>"{dir}/redirected.err"
echo "exit redirected $?" >&2
cp /run/stream "{dir}/auto.err"
n=0
until journalctl -D /run/log/journal -o json --no-pager SYSLOG_IDENTIFIER=skymesh-mqtt-broker \
    | grep -q 'bad configuration'; do
  n=$((n + 1)); [ $n -gt 600 ] && {{ echo "no entry in the journal" >&2; exit 92; }}
  sleep 0.05
done
journalctl -D /run/log/journal -o json --no-pager SYSLOG_IDENTIFIER=skymesh-mqtt-broker
"#,
        broker = broker.display(),
        config = config.display(),
        dir = dir.display(),
    );
    let out = Command::new("unshare")
        .args(["-m", "sh", "-c", &script])
        .output()
        .context("unshare")?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        bail!("namespace script failed: {:?}\n{stderr}", out.status);
    }
    for case in ["auto", "json", "redirected"] {
        let line = format!("exit {case} 64");
        if !stderr.contains(&line) {
            bail!("the {case} run did not exit 64:\n{stderr}");
        }
    }
    let entries = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(serde_json::from_str)
        .collect::<Result<Vec<serde_json::Value>, _>>()
        .context("journalctl -o json")?;
    let read = |name: &str| std::fs::read_to_string(dir.join(name)).unwrap_or_default();
    Ok(Journal {
        entries,
        stderr_auto: read("auto.err"),
        stderr_json: read("json.err"),
        stderr_redirected: read("redirected.err"),
    })
}

fn field<'a>(entry: &'a serde_json::Value, name: &str) -> &'a str {
    entry[name].as_str().unwrap_or("")
}

#[test]
fn under_a_journal_stream_services_log_to_journald_with_priority_and_fields() {
    let dir = tempfile::tempdir().expect("temp dir");
    let config: PathBuf = dir.path().join("broker.toml");
    std::fs::write(&config, BAD_CONFIG).expect("config");
    let broker = binary("skymesh-mqtt-broker");

    if let Some(why) = unavailable() {
        println!("journald not available: {why} (the fallback test still runs)");
        return;
    }
    let j = run_in_namespace(dir.path(), &broker, &config).expect("journald run");

    // One entry: the ERROR event, at priority 3 (err), its `error` field as a
    // prefixed journal field, the binary's name as the identifier.
    let bad: Vec<_> = j
        .entries
        .iter()
        .filter(|e| field(e, "MESSAGE") == "bad configuration")
        .collect();
    assert_eq!(bad.len(), 1, "{:#?}", j.entries);
    let e = bad[0];
    assert_eq!(field(e, "PRIORITY"), "3", "{e:#}");
    assert_eq!(
        field(e, "SYSLOG_IDENTIFIER"),
        "skymesh-mqtt-broker",
        "{e:#}"
    );
    assert!(
        field(e, "SKYMESH_ERROR").contains("listen"),
        "the error field names the config key: {e:#}"
    );
    assert_eq!(field(e, "TARGET"), "skymesh_runtime::service", "{e:#}");
    assert!(!field(e, "CODE_FILE").is_empty(), "{e:#}");
    // The journal got the event, not stderr (only the plain eprintln for a person
    // at a terminal is there).
    assert!(!j.stderr_auto.contains("ERROR"), "{}", j.stderr_auto);
    assert!(
        j.stderr_auto.contains("mqtt-broker: bad configuration"),
        "{}",
        j.stderr_auto
    );

    // `--log-format json` stays JSON on stderr under a journal stream.
    let json_line = j
        .stderr_json
        .lines()
        .find(|l| l.contains("bad configuration"))
        .unwrap_or_else(|| panic!("no JSON event on stderr:\n{}", j.stderr_json));
    let v: serde_json::Value = serde_json::from_str(json_line).expect("a JSON log line");
    assert_eq!(v["level"], "ERROR", "{v}");

    // A stderr that is not the journal stream (redirected, as the supervisor does
    // to a log file) keeps text there.
    assert!(
        j.stderr_redirected.contains("ERROR") && j.stderr_redirected.contains("bad configuration"),
        "{}",
        j.stderr_redirected
    );
}

/// With `JOURNAL_STREAM` naming stderr but no journald socket, `auto` chooses
/// journald, cannot reach it, and logs text on stderr with a warning saying so.
fn fallback_without_journald(broker: &Path, config: &Path) {
    if Path::new(HOST_SOCKET).exists() {
        println!("{HOST_SOCKET} exists here: the fallback is not checked");
        return;
    }
    let dir = config.parent().expect("temp dir");
    let stream = dir.join("stream");
    std::fs::write(&stream, "").expect("stream file");
    let meta = std::fs::metadata(&stream).expect("stat");
    let out = Command::new(broker)
        .args(["--config"])
        .arg(config)
        .arg("--check-config")
        .env("JOURNAL_STREAM", format!("{}:{}", meta.dev(), meta.ino()))
        .stderr(
            std::fs::File::options()
                .append(true)
                .open(&stream)
                .expect("open"),
        )
        .output()
        .expect("run the broker");
    assert_eq!(out.status.code(), Some(64));
    let text = std::fs::read_to_string(&stream).expect("stderr");
    assert!(
        text.contains("journald is not reachable") && text.contains("bad configuration"),
        "{text}"
    );
}

#[test]
fn without_journald_a_journal_stream_falls_back_to_text_and_says_so() {
    let dir = tempfile::tempdir().expect("temp dir");
    let config = dir.path().join("broker.toml");
    std::fs::write(&config, BAD_CONFIG).expect("config");
    fallback_without_journald(&binary("skymesh-mqtt-broker"), &config);
}
