//! Where a process's logs go: journald under systemd (priorities and structured
//! fields), human-readable text on a terminal or a pipe, or JSON lines when asked.
//!
//! `--log-format` / `SKYMESH_LOG_FORMAT` takes `auto` (the default), `text`, `json`
//! or `journald`. `auto` picks journald when systemd connected the process's stderr
//! to the journal: systemd then sets `JOURNAL_STREAM=<device>:<inode>` of that stream,
//! and the check compares it with stderr itself, as systemd documents, so a child
//! whose stderr was redirected elsewhere (a log file, a test's pipe) does not follow
//! an inherited `JOURNAL_STREAM` into the journal. Otherwise `auto` is text.

use std::fmt;
use std::io::IsTerminal;
use std::str::FromStr;

use tracing_journald::{Priority, PriorityMappings};
use tracing_subscriber::layer::SubscriberExt as _;
use tracing_subscriber::util::SubscriberInitExt as _;
use tracing_subscriber::EnvFilter;

/// The values `--log-format` accepts.
pub const LOG_FORMATS: [&str; 4] = ["auto", "text", "json", "journald"];

/// Prefix of the journal fields that carry an event's key-value fields
/// (`error = %e` → `SKYMESH_ERROR=...`): keeps them apart from journald's own
/// (`MESSAGE`, `PRIORITY`, `CODE_FILE`, ...).
pub const JOURNAL_FIELD_PREFIX: &str = "SKYMESH";

/// The log format asked for on the command line or in `SKYMESH_LOG_FORMAT`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LogFormat {
    /// journald when stderr is the journal stream systemd set up, else text.
    #[default]
    Auto,
    Text,
    Json,
    Journald,
}

impl FromStr for LogFormat {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "auto" => Ok(LogFormat::Auto),
            "text" => Ok(LogFormat::Text),
            "json" => Ok(LogFormat::Json),
            "journald" => Ok(LogFormat::Journald),
            other => Err(format!(
                "`{other}` is not a log format ({})",
                LOG_FORMATS.join(", ")
            )),
        }
    }
}

impl fmt::Display for LogFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            LogFormat::Auto => "auto",
            LogFormat::Text => "text",
            LogFormat::Json => "json",
            LogFormat::Journald => "journald",
        })
    }
}

/// What the process's surroundings say about its stderr.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Surroundings {
    /// `JOURNAL_STREAM` as set by systemd (`<device>:<inode>`).
    pub journal_stream: Option<String>,
    /// Device and inode of the open stderr.
    pub stderr_id: Option<(u64, u64)>,
    /// stderr is a terminal.
    pub stderr_terminal: bool,
    /// `NO_COLOR` is set (to anything but the empty string).
    pub no_color: bool,
}

impl Surroundings {
    /// Those of this process.
    // `dev_t` and `ino_t` are not 64 bits on every target.
    #[allow(clippy::unnecessary_cast)]
    pub fn of_this_process() -> Self {
        let stderr = std::io::stderr();
        Surroundings {
            journal_stream: std::env::var("JOURNAL_STREAM").ok(),
            stderr_id: nix::sys::stat::fstat(&stderr)
                .ok()
                .map(|s| (s.st_dev as u64, s.st_ino as u64)),
            stderr_terminal: stderr.is_terminal(),
            no_color: std::env::var_os("NO_COLOR").is_some_and(|v| !v.is_empty()),
        }
    }

    /// stderr is the stream `JOURNAL_STREAM` names.
    pub fn stderr_is_journal(&self) -> bool {
        match (self.journal_stream.as_deref(), self.stderr_id) {
            (Some(stream), Some(id)) => parse_journal_stream(stream) == Some(id),
            _ => false,
        }
    }
}

/// `<device>:<inode>`, both decimal, as systemd writes `JOURNAL_STREAM`.
pub fn parse_journal_stream(s: &str) -> Option<(u64, u64)> {
    let (dev, ino) = s.trim().split_once(':')?;
    Some((dev.parse().ok()?, ino.parse().ok()?))
}

/// Where the log lines of a process go.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sink {
    /// journald's native socket: one entry per event, with its priority and fields.
    Journald,
    /// Human-readable lines on stderr, coloured only on a terminal without `NO_COLOR`.
    Text { ansi: bool },
    /// One JSON object per line on stderr.
    Json,
}

/// The sink for `format` in `env` (pure: the choice, not the connection).
pub fn choose(format: LogFormat, env: &Surroundings) -> Sink {
    let text = Sink::Text {
        ansi: env.stderr_terminal && !env.no_color,
    };
    match format {
        LogFormat::Json => Sink::Json,
        LogFormat::Text => text,
        LogFormat::Journald => Sink::Journald,
        LogFormat::Auto if env.stderr_is_journal() => Sink::Journald,
        LogFormat::Auto => text,
    }
}

/// The journald layer: tracing's levels on syslog's priorities, each on its own
/// name (info is `info`, not tracing-journald's default `notice`), so
/// `journalctl -p warning` shows warnings and errors. Fails when journald's socket
/// cannot be reached.
pub fn journald_layer() -> std::io::Result<tracing_journald::Layer> {
    Ok(tracing_journald::layer()?
        .with_field_prefix(Some(JOURNAL_FIELD_PREFIX.to_owned()))
        .with_priority_mappings(PriorityMappings {
            error: Priority::Error,
            warn: Priority::Warning,
            info: Priority::Informational,
            debug: Priority::Debug,
            trace: Priority::Debug,
        }))
}

fn filter() -> EnvFilter {
    EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"))
}

/// Installs the global subscriber for `format` (`RUST_LOG` filters, default
/// `info`); returns the sink in use. Logs go to `file` when given (text without
/// colour, or JSON), else as [`choose`] says. When journald was chosen but cannot
/// be reached, logs go to stderr as text and a warning says why.
pub fn init(format: LogFormat, file: Option<std::fs::File>) -> Sink {
    let registry = tracing_subscriber::registry().with(filter());
    if let Some(file) = file {
        let writer = std::sync::Mutex::new(file);
        let fmt = tracing_subscriber::fmt::layer().with_writer(writer);
        return if format == LogFormat::Json {
            let _ = registry.with(fmt.json()).try_init();
            Sink::Json
        } else {
            let _ = registry.with(fmt.with_ansi(false)).try_init();
            Sink::Text { ansi: false }
        };
    }
    let env = Surroundings::of_this_process();
    let sink = choose(format, &env);
    let stderr_text = |ansi| {
        tracing_subscriber::fmt::layer()
            .with_ansi(ansi)
            .with_writer(std::io::stderr)
    };
    match sink {
        Sink::Json => {
            let json = tracing_subscriber::fmt::layer()
                .json()
                .with_writer(std::io::stderr);
            let _ = registry.with(json).try_init();
            sink
        }
        Sink::Text { ansi } => {
            let _ = registry.with(stderr_text(ansi)).try_init();
            sink
        }
        Sink::Journald => match journald_layer() {
            Ok(layer) => {
                let _ = registry.with(layer).try_init();
                sink
            }
            Err(e) => {
                let ansi = env.stderr_terminal && !env.no_color;
                let _ = registry.with(stderr_text(ansi)).try_init();
                tracing::warn!(
                    error = %e,
                    format = %format,
                    "journald is not reachable: logging to stderr as text"
                );
                Sink::Text { ansi }
            }
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(journal_stream: Option<&str>, stderr_id: Option<(u64, u64)>) -> Surroundings {
        Surroundings {
            journal_stream: journal_stream.map(str::to_owned),
            stderr_id,
            stderr_terminal: false,
            no_color: false,
        }
    }

    #[test]
    fn formats_parse_and_print() {
        for name in LOG_FORMATS {
            let f: LogFormat = name.parse().unwrap();
            assert_eq!(f.to_string(), name);
        }
        assert_eq!(LogFormat::default(), LogFormat::Auto);
        let e = "xml".parse::<LogFormat>().unwrap_err();
        assert!(e.contains("auto, text, json, journald"), "{e}");
    }

    #[test]
    fn journal_stream_is_device_colon_inode() {
        assert_eq!(parse_journal_stream("8:123456"), Some((8, 123456)));
        assert_eq!(parse_journal_stream(" 64768:99\n"), Some((64768, 99)));
        for bad in ["", "8", "8:", ":9", "a:9", "8:9:10", "-1:9"] {
            assert_eq!(parse_journal_stream(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn auto_is_journald_only_when_stderr_is_the_journal_stream() {
        let journal = env(Some("8:42"), Some((8, 42)));
        assert!(journal.stderr_is_journal());
        assert_eq!(choose(LogFormat::Auto, &journal), Sink::Journald);
        // An inherited JOURNAL_STREAM with stderr redirected elsewhere (a log file, a
        // pipe), a malformed one, no JOURNAL_STREAM, or an unknown stderr: text.
        for other in [
            env(Some("8:42"), Some((8, 43))),
            env(Some("9:42"), Some((8, 42))),
            env(Some("garbage"), Some((8, 42))),
            env(None, Some((8, 42))),
            env(Some("8:42"), None),
        ] {
            assert_eq!(
                choose(LogFormat::Auto, &other),
                Sink::Text { ansi: false },
                "{other:?}"
            );
        }
    }

    #[test]
    fn explicit_formats_win_over_the_journal_stream() {
        let journal = env(Some("8:42"), Some((8, 42)));
        assert_eq!(choose(LogFormat::Json, &journal), Sink::Json);
        assert_eq!(
            choose(LogFormat::Text, &journal),
            Sink::Text { ansi: false }
        );
        assert_eq!(
            choose(LogFormat::Journald, &env(None, None)),
            Sink::Journald
        );
    }

    #[test]
    fn colour_only_on_a_terminal_without_no_color() {
        let mut e = env(None, Some((1, 2)));
        e.stderr_terminal = true;
        assert_eq!(choose(LogFormat::Auto, &e), Sink::Text { ansi: true });
        assert_eq!(choose(LogFormat::Text, &e), Sink::Text { ansi: true });
        e.no_color = true;
        assert_eq!(choose(LogFormat::Auto, &e), Sink::Text { ansi: false });
        e.stderr_terminal = false;
        e.no_color = false;
        assert_eq!(choose(LogFormat::Auto, &e), Sink::Text { ansi: false });
    }

    /// This process's own stderr: its identity is what systemd would put in
    /// `JOURNAL_STREAM`, so naming it there makes `auto` choose journald.
    #[test]
    fn this_process_matches_a_journal_stream_naming_its_stderr() {
        let mut here = Surroundings::of_this_process();
        let (dev, ino) = here.stderr_id.expect("stderr is open in tests");
        here.journal_stream = Some(format!("{dev}:{ino}"));
        assert_eq!(choose(LogFormat::Auto, &here), Sink::Journald);
        here.journal_stream = Some(format!("{dev}:{}", ino + 1));
        assert!(matches!(choose(LogFormat::Auto, &here), Sink::Text { .. }));
    }
}
