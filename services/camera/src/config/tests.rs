//! Tests of the camera's configuration: defaults, validation, synthetic scene.

use super::*;
use skymesh_runtime::config::parse;

fn with(edits: &[(&str, &str)]) -> Result<Settings, ConfigError> {
    let mut text = RawConfig::DEFAULT_TOML.to_string();
    for (from, to) in edits {
        assert!(text.contains(from), "the shipped config has no `{from}`");
        text = text.replace(from, to);
    }
    parse::<RawConfig>(&text, "test")
}

#[test]
fn the_shipped_config_parses_to_the_defaults() {
    let s = with(&[]).unwrap();
    assert_eq!((s.width, s.height, s.fps), (1280, 720, 30));
    assert_eq!(s.format, PixelFormat::Rgb24);
    assert_eq!(s.stream, "main");
    assert_eq!(s.intrinsics.lens, Lens::Pinhole);
    assert!((s.intrinsics.fx - 640.0).abs() < 1e-9 && s.intrinsics.fx == s.intrinsics.fy);
    assert_eq!((s.intrinsics.cx, s.intrinsics.cy), (639.5, 359.5));
    assert_eq!(s.synthetic.targets.len(), 3);
    assert_eq!(s.source, Source::Synthetic);
    assert_eq!(s.synthetic.origin, None);
    assert_eq!(s.frame_len(), 1280 * 720 * 3);
    // An empty file gives the same camera, without targets.
    let empty = parse::<RawConfig>("", "empty").unwrap();
    assert_eq!(empty.intrinsics, s.intrinsics);
    assert!(empty.synthetic.targets.is_empty());
}

#[test]
fn bad_values_are_refused_naming_the_field() {
    for (edit, field) in [
        (("stream = \"main\"", "stream = \"toolongname\""), "stream"),
        (("stream = \"main\"", "stream = \"a/b\""), "stream"),
        (("width = 1280", "width = 2000"), "width"),
        (("fps = 30", "fps = 0"), "fps"),
        (
            ("render_threads = 2", "render_threads = 0"),
            "synthetic.render_threads",
        ),
        (("fps = 30", "fps = 61"), "fps"),
        (("format = \"rgb24\"", "format = \"yuyv\""), "format"),
        (("model = \"pinhole\"", "model = \"fancy\""), "lens.model"),
        (("hfov_deg = 90.0", "hfov_deg = 179.0"), "lens.hfov_deg"),
        (("source = \"synthetic\"", "source = \"v4l2\""), "source"),
        (("id = 2", "id = 1"), "synthetic.targets[1].id"),
        (
            ("size_m = 3.0", "size_m = 0.0"),
            "synthetic.targets[0].size_m",
        ),
    ] {
        let e = with(&[edit]).unwrap_err();
        assert!(
            matches!(&e, ConfigError::Invalid { field: f, .. } if f == field),
            "{edit:?}: {e}"
        );
    }
    let e = with(&[
        ("width = 1280", "width = 1281"),
        ("format = \"rgb24\"", "format = \"nv12\""),
    ])
    .unwrap_err();
    assert!(e.to_string().contains("even"), "{e}");
    let e = with(&[(
        "size_m = 3.0",
        "size_m = 3.0\nline = { from_ne_m = [0.0, 0.0], to_ne_m = [1.0, 1.0], speed_mps = 1.0 }",
    )])
    .unwrap_err();
    assert!(e.to_string().contains("exactly one"), "{e}");
    assert!(matches!(
        with(&[("fps = 30", "fps = 30\nbogus = 1")]),
        Err(ConfigError::Parse { .. })
    ));
}

#[test]
fn fisheye_nv12_and_an_origin_parse() {
    let s = with(&[
        ("model = \"pinhole\"", "model = \"fisheye\""),
        ("hfov_deg = 90.0", "hfov_deg = 180.0"),
        ("format = \"rgb24\"", "format = \"nv12\""),
        ("# origin = {", "origin = {"),
    ])
    .unwrap();
    assert_eq!(s.intrinsics.lens, Lens::Fisheye);
    assert!((s.intrinsics.fx - 640.0 / std::f64::consts::FRAC_PI_2).abs() < 1e-9);
    assert_eq!(s.frame_len(), 1280 * 720 * 3 / 2);
    assert_eq!(s.synthetic.origin.map(|o| o.ground_alt_msl_m), Some(488.0));
}
