//! Tests of the Y4M source's configuration checks against real files.

use super::*;
use skymesh_runtime::config::parse;
use std::sync::atomic::{AtomicU32, Ordering};

use crate::y4m::Chroma;

/// A Y4M file of `frames` grey frames in the temp dir (removed on drop).
struct TempY4m(PathBuf);

impl TempY4m {
    fn new(header_line: &str, frames: usize, frame_len: usize) -> Self {
        static N: AtomicU32 = AtomicU32::new(0);
        let path = std::env::temp_dir().join(format!(
            "skymesh-camera-config-{}-{}.y4m",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let mut data = header_line.as_bytes().to_vec();
        for _ in 0..frames {
            data.extend_from_slice(b"FRAME\n");
            data.extend(std::iter::repeat_n(100u8, frame_len));
        }
        std::fs::write(&path, data).expect("write the test file");
        TempY4m(path)
    }
}

impl Drop for TempY4m {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn config(path: &Path, extra: &str) -> Result<Settings, ConfigError> {
    let text = format!(
        "source = \"y4m\"\nwidth = 64\nheight = 48\n[y4m]\npath = \"{}\"\n{extra}",
        path.display()
    );
    parse::<RawConfig>(&text, "test")
}

#[test]
fn a_y4m_file_of_the_configured_size_is_accepted() {
    let f = TempY4m::new("YUV4MPEG2 W64 H48 F25:1 C420jpeg\n", 2, 64 * 48 * 3 / 2);
    let s = config(&f.0, "").unwrap();
    let Source::Y4m(y) = &s.source else {
        panic!("not a y4m source: {:?}", s.source)
    };
    assert_eq!(y.path, f.0);
    assert!(y.looping);
    assert_eq!(y.range, Range::Full);
    assert_eq!((y.header.width, y.header.height), (64, 48));
    assert_eq!(y.header.chroma, Chroma::C420);
    let s = config(&f.0, "loop = false\nrange = \"limited\"").unwrap();
    assert!(matches!(
        s.source,
        Source::Y4m(Y4mSettings {
            looping: false,
            range: Range::Limited,
            ..
        })
    ));
    // The shipped config is the synthetic source.
    assert_eq!(
        parse::<RawConfig>("", "empty").unwrap().source,
        Source::Synthetic
    );
}

#[test]
fn a_size_mismatch_names_the_file_and_both_sizes() {
    let f = TempY4m::new("YUV4MPEG2 W80 H60 F25:1\n", 1, 80 * 60 * 3 / 2);
    let e = config(&f.0, "").unwrap_err();
    let text = e.to_string();
    assert!(
        matches!(&e, ConfigError::Invalid { field, .. } if field == "y4m.path"),
        "{e}"
    );
    assert!(text.contains(&f.0.display().to_string()), "{text}");
    assert!(text.contains("80×60") && text.contains("64×48"), "{text}");
}

#[test]
fn bad_y4m_settings_and_files_are_refused() {
    let f422 = TempY4m::new("YUV4MPEG2 W64 H48 C422\n", 0, 0);
    let e = config(&f422.0, "").unwrap_err().to_string();
    assert!(e.contains("C422") && e.contains("not supported"), "{e}");
    let junk = TempY4m::new("GIF89a\n", 0, 0);
    let e = config(&junk.0, "").unwrap_err().to_string();
    assert!(e.contains("at byte 0"), "{e}");
    let e = config(Path::new("/nonexistent/skymesh/x.y4m"), "")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("cannot open") && e.contains("/nonexistent/skymesh/x.y4m"),
        "{e}"
    );
    let e = config(Path::new("relative.y4m"), "")
        .unwrap_err()
        .to_string();
    assert!(e.contains("absolute"), "{e}");
    let e = parse::<RawConfig>("source = \"y4m\"", "test").unwrap_err();
    assert!(
        matches!(&e, ConfigError::Invalid { field, .. } if field == "y4m.path"),
        "{e}"
    );
    let ok = TempY4m::new("YUV4MPEG2 W64 H48\n", 1, 64 * 48 * 3 / 2);
    let e = config(&ok.0, "range = \"tv\"").unwrap_err();
    assert!(
        matches!(&e, ConfigError::Invalid { field, .. } if field == "y4m.range"),
        "{e}"
    );
    assert!(matches!(
        config(&ok.0, "looping = true"),
        Err(ConfigError::Parse { .. })
    ));
}

/// Found by the config_files fuzz target's check for readers that can hang: a
/// device, FIFO or directory as `y4m.path` is refused without reading it.
#[test]
fn devices_fifos_and_directories_are_refused_without_reading() {
    let dir = std::env::temp_dir();
    let mut refused = vec![PathBuf::from("/dev/zero"), PathBuf::from("/dev/null"), dir];
    let fifo =
        std::env::temp_dir().join(format!("skymesh-camera-config-{}.fifo", std::process::id()));
    let _ = std::fs::remove_file(&fifo);
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        refused.push(fifo.clone());
    }
    for p in &refused {
        let e = config(p, "").unwrap_err();
        assert!(
            matches!(&e, ConfigError::Invalid { field, .. } if field == "y4m.path"),
            "{}: {e}",
            p.display()
        );
        assert!(e.to_string().contains("not a regular file"), "{e}");
    }
    let _ = std::fs::remove_file(&fifo);
    // Whatever stdin is here (a terminal, a pipe, /dev/null, a file), it returns.
    assert!(config(Path::new("/dev/stdin"), "").is_err());
}
