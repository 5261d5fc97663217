//! The shipped file, conversions and refusals.

use super::*;

fn parse(text: &str) -> Result<Settings, ConfigError> {
    let raw: RawConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
        origin: "test".into(),
        message: e.to_string(),
    })?;
    raw.validate_with_env(None, Some("t"))
}

#[test]
fn shipped_file_parses_with_the_documented_set() {
    let s = parse(DEFAULT_CONFIG_TOML).unwrap();
    let names = |v: Vec<&str>| v.join(",");
    assert_eq!(
        names(s.leds.iter().map(|l| l.name.as_str()).collect()),
        "status,red,green,blue"
    );
    assert!(s.leds.iter().all(|l| l.backend == LedBackend::Sim));
    assert_eq!(
        names(s.gpios.iter().map(|g| g.name.as_str()).collect()),
        "payload_release,button_a"
    );
    assert!(s.gpios[0].output && !s.gpios[1].output);
    assert_eq!(
        names(s.channels.iter().map(|c| c.name.as_str()).collect()),
        "camera,radio,lights"
    );
    assert_eq!(s.lcd.backend, LcdBackend::Sim);
    assert_eq!(s.lcd.width, 16);
    assert!(
        s.power.power_down_command.is_empty(),
        "never power off by default"
    );
    assert!(s.power.power_up_command.is_empty());
    assert_eq!(s.power.power_down_delay, Duration::from_secs(10));
    assert_eq!(s.restart_delay, Duration::from_secs(1));
    assert_eq!(s.state_dir, PathBuf::from("/tmp/skymesh-t/hardware"));
    // Empty file: nothing configured, still valid.
    let empty = parse("").unwrap();
    assert!(empty.leds.is_empty() && empty.channels.is_empty());
    assert_eq!(empty.lcd.backend, LcdBackend::None);
}

#[test]
fn state_dir_follows_systemd_then_the_domain() {
    assert_eq!(
        default_state_dir(Some("/var/lib/skymesh"), Some("x")),
        PathBuf::from("/var/lib/skymesh/hardware")
    );
    assert_eq!(
        default_state_dir(Some("/var/lib/a:/var/lib/b"), None),
        PathBuf::from("/var/lib/a/hardware")
    );
    assert_eq!(
        default_state_dir(None, None),
        PathBuf::from("/tmp/skymesh-skymesh/hardware")
    );
    let s = parse("state_dir = \"/srv/hw\"").unwrap();
    assert_eq!(s.state_dir, PathBuf::from("/srv/hw"));
}

#[test]
fn backends_are_converted() {
    let s = parse(
        r#"
        [[led]]
        name = "act"
        backend = "sysfs"
        [[led]]
        name = "x"
        backend = "sysfs"
        path = "/sys/class/leds/led1"
        [[gpio]]
        name = "g"
        direction = "input"
        backend = "cdev"
        line = 17
        active_low = true
        [[power_channel]]
        name = "p"
        backend = "cdev"
        chip = "/dev/gpiochip1"
        line = 3
        default = "on"
        "#,
    )
    .unwrap();
    assert_eq!(
        s.leds[0].backend,
        LedBackend::Sysfs {
            dir: "/sys/class/leds/act".into()
        }
    );
    assert_eq!(
        s.leds[1].backend,
        LedBackend::Sysfs {
            dir: "/sys/class/leds/led1".into()
        }
    );
    assert_eq!(
        s.gpios[0].backend,
        LineBackend::Cdev {
            chip: "/dev/gpiochip0".into(),
            line: 17
        }
    );
    assert!(!s.gpios[0].output && s.gpios[0].active_low);
    assert_eq!(
        s.channels[0].backend,
        LineBackend::Cdev {
            chip: "/dev/gpiochip1".into(),
            line: 3
        }
    );
    assert!(s.channels[0].default_on);
}

#[test]
fn bad_configs_are_refused_naming_the_field() {
    let many_leds: String = (0..17)
        .map(|i| format!("[[led]]\nname = \"l{i}\"\n"))
        .collect();
    let long = "x".repeat(33);
    for (text, field) in [
        ("bogus = 1", "bogus"),
        ("[[led]]\nname = \"a\"\n[[led]]\nname = \"a\"", "twice"),
        (&format!("[[led]]\nname = \"{long}\""), "led.name"),
        ("[[led]]\nname = \"a/b\"", "led.name"),
        ("[[led]]\nname = \".a\"", "led.name"),
        ("[[led]]\nname = \"\"", "led.name"),
        (&many_leds, "at most 16"),
        ("[[led]]\nname = \"a\"\npath = \"/x\"", "only for backend"),
        (
            "[[led]]\nname = \"a\"\nbackend = \"pwm\"",
            "unknown variant",
        ),
        ("[[gpio]]\nname = \"a\"", "direction"),
        (
            "[[gpio]]\nname = \"a\"\ndirection = \"output\"\nbackend = \"cdev\"",
            "line",
        ),
        (
            "[[gpio]]\nname = \"a\"\ndirection = \"output\"\nline = 3",
            "only for backend",
        ),
        (
            "[[gpio]]\nname = \"a\"\ndirection = \"output\"\ninitial = 2",
            "initial",
        ),
        (
            "[[gpio]]\nname = \"a\"\ndirection = \"output\"\nbackend = \"cdev\"\nline = 1\n\
             [[power_channel]]\nname = \"b\"\nbackend = \"cdev\"\nline = 1\ndefault = \"on\"",
            "configured twice",
        ),
        ("[[power_channel]]\nname = \"a\"", "default"),
        (
            "[[power_channel]]\nname = \"a\"\ndefault = \"maybe\"",
            "unknown variant",
        ),
        ("state_dir = \"relative/dir\"", "state_dir"),
        ("restart_delay_s = 0.0", "restart_delay_s"),
        ("restart_delay_s = nan", "restart_delay_s"),
        ("[lcd]\nwidth = 41", "lcd.width"),
        ("[lcd]\nbackend = \"hd44780\"", "unknown variant"),
        ("[power]\npower_down_delay_s = -1.0", "power_down_delay_s"),
        ("[power]\npower_down_command = [\"\"]", "power_down_command"),
    ] {
        let e = parse(text).unwrap_err();
        assert!(e.to_string().contains(field), "{text}: {e}");
    }
}
