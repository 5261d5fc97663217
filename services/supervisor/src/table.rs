//! The status table: printed once by `skymesh status`, redrawn about once a second by
//! `skymesh up` when stdout is a terminal.

use std::fmt::Write;
use std::io::Write as _;
use std::time::Instant;

use crate::state::{Event, StatusEntry};

/// `4.2s`, `3m07s`, `2h05m`, `3d04h`.
pub fn human_duration(secs: f64) -> String {
    if !secs.is_finite() || secs < 0.0 {
        return "-".to_string();
    }
    let s = secs as u64;
    match s {
        0..=59 => format!("{secs:.1}s"),
        60..=3599 => format!("{}m{:02}s", s / 60, s % 60),
        3600..=86_399 => format!("{}h{:02}m", s / 3600, (s % 3600) / 60),
        _ => format!("{}d{:02}h", s / 86_400, (s % 86_400) / 3600),
    }
}

/// The table of services, columns aligned, one line each, ending in a newline.
pub fn render(rows: &[StatusEntry]) -> String {
    let header = [
        "SERVICE",
        "PID",
        "STATE",
        "RESTARTS",
        "UPTIME",
        "HEARTBEAT",
        "LAST EXIT",
    ];
    let cells: Vec<[String; 7]> = rows
        .iter()
        .map(|r| {
            [
                if r.critical {
                    format!("{}*", r.name)
                } else {
                    r.name.clone()
                },
                r.pid.map_or("-".into(), |p| p.to_string()),
                r.state.clone(),
                r.restarts.to_string(),
                if r.pid.is_some() {
                    human_duration(r.uptime_s)
                } else {
                    "-".into()
                },
                r.heartbeat_age_s
                    .map_or("-".into(), |a| format!("{} ago", human_duration(a))),
                r.last_exit_code.map_or("-".into(), |c| c.to_string()),
            ]
        })
        .collect();
    let mut widths = header.map(str::len);
    for row in &cells {
        for (w, c) in widths.iter_mut().zip(row) {
            *w = (*w).max(c.chars().count());
        }
    }
    let mut out = String::new();
    let mut line = |cols: &[String]| {
        let mut l = String::new();
        for (i, (c, w)) in cols.iter().zip(widths).enumerate() {
            if i + 1 == cols.len() {
                l.push_str(c);
            } else {
                let _ = write!(l, "{c:<w$}  ");
            }
        }
        out.push_str(l.trim_end());
        out.push('\n');
    };
    line(&header.map(String::from));
    for row in &cells {
        line(row);
    }
    if rows.iter().any(|r| r.critical) {
        out.push_str("(* critical)\n");
    }
    out
}

/// What the live view shows around the table.
#[derive(Debug, Clone)]
pub struct LiveHeader {
    pub domain: String,
    pub http: String,
    pub logs: Option<String>,
    pub monitor_only: bool,
}

/// One frame of the live view: cursor home, each line cleared to its end, and the
/// rest of the screen cleared (no full-screen clear, so it does not flicker).
pub fn live_frame(
    h: &LiveHeader,
    rows: &[StatusEntry],
    events: &[Event],
    started: Instant,
    now: Instant,
) -> String {
    let mut body = String::new();
    let mode = if h.monitor_only {
        "monitor-only"
    } else {
        "supervising"
    };
    let _ = writeln!(
        body,
        "skymesh {mode} · domain {} · {} · up {}",
        h.domain,
        h.http,
        human_duration(now.saturating_duration_since(started).as_secs_f64())
    );
    body.push('\n');
    body.push_str(&render(rows));
    if !events.is_empty() {
        body.push_str("\nrecent:\n");
        for e in events {
            let ago = now.saturating_duration_since(e.at).as_secs_f64();
            let _ = writeln!(body, "  {:>8} ago  {}", human_duration(ago), e.text);
        }
    }
    if let Some(l) = &h.logs {
        let _ = writeln!(body, "\nlogs: {l}");
    }
    body.push_str("Ctrl-C stops the mesh.\n");
    let mut out = String::from("\x1b[H");
    for line in body.lines() {
        out.push_str(line);
        out.push_str("\x1b[K\n");
    }
    out.push_str("\x1b[J");
    out
}

/// Writes a frame to stdout; a closed terminal is not an error worth stopping for.
pub fn draw(frame: &str) {
    let mut out = std::io::stdout().lock();
    let _ = out.write_all(frame.as_bytes());
    let _ = out.flush();
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(name: &str, pid: Option<u32>, state: &str) -> StatusEntry {
        StatusEntry {
            name: name.into(),
            pid,
            state: state.into(),
            restarts: 2,
            uptime_s: 125.0,
            heartbeat_age_s: Some(0.25),
            last_exit_code: None,
            critical: pid.is_some(),
            adopted: false,
        }
    }

    #[test]
    fn durations_are_short() {
        assert_eq!(human_duration(4.25), "4.2s");
        assert_eq!(human_duration(187.0), "3m07s");
        assert_eq!(human_duration(7500.0), "2h05m");
        assert_eq!(human_duration(3.0 * 86_400.0 + 4.0 * 3600.0), "3d04h");
        assert_eq!(human_duration(f64::NAN), "-");
    }

    #[test]
    fn table_columns_line_up() {
        let t = render(&[
            row("vehicle-sim", Some(1234), "running"),
            row("autopilot-link", None, "backoff"),
        ]);
        let lines: Vec<&str> = t.lines().collect();
        assert!(lines[0].starts_with("SERVICE"), "{t}");
        let col = lines[0].find("PID").unwrap();
        assert_eq!(&lines[1][col..col + 4], "1234", "{t}");
        assert_eq!(&lines[2][col..col + 1], "-", "{t}");
        assert!(
            lines[1].contains("2m05s") && lines[1].contains("0.2s ago"),
            "{t}"
        );
        assert!(lines[1].starts_with("vehicle-sim*"));
        assert!(t.ends_with("(* critical)\n"));
    }

    #[test]
    fn live_frame_redraws_in_place() {
        let h = LiveHeader {
            domain: "d".into(),
            http: "http://127.0.0.1:9464".into(),
            logs: Some("/tmp/x/<service>.log".into()),
            monitor_only: false,
        };
        let now = Instant::now();
        let f = live_frame(
            &h,
            &[row("a", Some(1), "running")],
            &[Event {
                at: now,
                text: "a: starting → running".into(),
            }],
            now,
            now,
        );
        assert!(f.starts_with("\x1b[H") && f.ends_with("\x1b[J"));
        assert!(f.contains("logs: /tmp/x/<service>.log"));
        assert!(f.contains("a: starting → running"));
    }
}
