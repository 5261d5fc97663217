use super::*;

fn parse(text: &str) -> Result<Settings, ConfigError> {
    Settings::parse(text, "test", Path::new("/etc/skymesh"))
}

#[test]
fn shipped_config_parses_with_the_default_mesh() {
    let s = parse(DEFAULT_TOML).expect("deploy/skymesh.toml must be valid");
    let names: Vec<&str> = s.services.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(&names[..2], ["vehicle-sim", "autopilot-link"]);
    assert_eq!(s.metrics, DEFAULT_METRICS.parse().unwrap());
    assert_eq!(s.missed_heartbeats, 6);
    assert_eq!(s.grace, Duration::from_secs(5));
    assert_eq!(
        s.ipc_config,
        Some(PathBuf::from("/etc/skymesh/iceoryx2.toml"))
    );
    let vs = s.service("vehicle-sim").unwrap();
    assert_eq!(
        vs.config,
        Some(PathBuf::from("/etc/skymesh/vehicle-sim.toml"))
    );
    assert_eq!(vs.program, PathBuf::from("skymesh-vehicle-sim"));
    assert!(s.service("autopilot-link").unwrap().after == ["vehicle-sim"]);
    // The control path runs real-time; the frame path does not.
    let prio = |n: &str| s.service(n).unwrap().realtime_priority;
    assert_eq!(prio("autopilot-link"), Some(30));
    assert_eq!(prio("dji-gateway"), Some(20));
    assert_eq!(prio("mqtt-broker"), Some(20));
    let cpus = |n: &str| s.service(n).unwrap().cpu_affinity.clone();
    assert_eq!(cpus("autopilot-link").as_deref(), Some("1"));
    assert_eq!(cpus("dji-gateway").as_deref(), Some("1"));
    for normal in ["camera", "vision-pipeline", "vehicle-sim", "hardware"] {
        assert_eq!((prio(normal), cpus(normal)), (None, None), "{normal}");
    }
    // The shipped [restart] table spells out the built-in defaults.
    assert!(s
        .services
        .iter()
        .all(|x| x.restart == RestartPolicy::default()));
}

#[test]
fn realtime_priority_and_cpu_affinity_are_optional() {
    let s = parse(
        "[[service]]\nname = \"a\"\nbinary = \"x\"\nrealtime_priority = 20\n\
         [[service]]\nname = \"b\"\nbinary = \"x\"\nrealtime_priority = 0\n\
         [[service]]\nname = \"c\"\nbinary = \"x\"\n",
    )
    .unwrap();
    let prio = |n: &str| s.service(n).unwrap().realtime_priority;
    assert_eq!((prio("a"), prio("b"), prio("c")), (Some(20), None, None));
    let s = parse(
        "[[service]]\nname = \"a\"\nbinary = \"x\"\ncpu_affinity = [2, 3]\n\
         [[service]]\nname = \"b\"\nbinary = \"x\"\ncpu_affinity = []\n",
    )
    .unwrap();
    assert_eq!(s.service("a").unwrap().cpu_affinity.as_deref(), Some("2,3"));
    assert_eq!(s.service("b").unwrap().cpu_affinity, None);
}

#[test]
fn empty_file_is_an_empty_mesh_with_defaults() {
    let s = parse("").unwrap();
    assert!(s.services.is_empty());
    assert_eq!(s.heartbeat, Duration::from_millis(500));
    assert_eq!(s.ipc_config, None);
    assert_eq!(s.vehicles, [1]);
    assert_eq!(s.console, ConsoleSettings::default());
}

#[test]
fn vehicles_are_system_ids_listed_once() {
    let s = parse("[supervisor]\nvehicles = [3, 1, 255]").unwrap();
    assert_eq!(s.vehicles, [1, 3, 255]);
    assert!(parse("[supervisor]\nvehicles = []")
        .unwrap()
        .vehicles
        .is_empty());
    for bad in ["[0]", "[256]", "[-1]", "[2, 2]", "1", "[\"1\"]"] {
        let e = parse(&format!("[supervisor]\nvehicles = {bad}")).unwrap_err();
        assert!(e.to_string().contains("vehicles"), "{bad}: {e}");
    }
}

#[test]
fn start_order_follows_after_and_keeps_file_order_for_ties() {
    let s = parse(
        r#"
        [[service]]
        name = "c"
        binary = "x"
        after = ["b"]
        [[service]]
        name = "a"
        binary = "x"
        [[service]]
        name = "b"
        binary = "x"
        after = ["a"]
        [[service]]
        name = "d"
        binary = "x"
        "#,
    )
    .unwrap();
    let names: Vec<&str> = s.services.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["a", "b", "c", "d"]);
}

#[test]
fn cycles_and_unknown_names_are_config_errors() {
    let e = parse(
        r#"
        [[service]]
        name = "a"
        binary = "x"
        after = ["b"]
        [[service]]
        name = "b"
        binary = "x"
        after = ["a"]
        [[service]]
        name = "c"
        binary = "x"
        "#,
    )
    .unwrap_err();
    assert!(e.to_string().contains("cycle among a, b"), "{e}");
    let e = parse("[[service]]\nname = \"a\"\nbinary = \"x\"\nafter = [\"zz\"]\n").unwrap_err();
    assert!(e.to_string().contains("zz"), "{e}");
    let e = parse("[[service]]\nname = \"a\"\nbinary = \"x\"\nafter = [\"a\"]\n").unwrap_err();
    assert!(e.to_string().contains("itself"), "{e}");
}

#[test]
fn bad_values_name_the_field() {
    for (text, needle) in [
        ("[supervisor]\nmetrics = \"nope\"", "supervisor.metrics"),
        ("[supervisor]\nheartbeat_ms = 1", "supervisor.heartbeat_ms"),
        ("[supervisor]\nbogus = 1", "bogus"),
        ("[supervisor]\nconsole_token = \"short\"", "supervisor.console_token"),
        ("[supervisor]\nconsole_token = \"0123456789abcdef\"\nconsole_token_file = \"t\"", "supervisor.console_token_file"),
        ("[supervisor]\nconsole_remote = \"yes\"", "console_remote"),
        ("[restart]\nmode = \"never\"", "restart.mode"),
        ("[restart]\ninitial_backoff_ms = 500\nmax_backoff_ms = 100", "restart.max_backoff_ms"),
        ("[[service]]\nname = \"a/b\"\nbinary = \"x\"", "service[0].name"),
        ("[[service]]\nname = \"a\"\nbinary = \"x\"\n[[service]]\nname = \"a\"\nbinary = \"y\"", "more than one"),
        ("[[service]]\nname = \"a\"\nbinary = \"x\"\nenv = { SKYMESH_DOMAIN = \"x\" }", "SKYMESH_DOMAIN"),
        ("[[service]]\nname = \"a\"\nbinary = \"x\"\nrestart = { budget = -1 }", "budget"),
        ("[[service]]\nname = \"a\"\nbinary = \"x\"\ncolour = \"red\"", "colour"),
        ("[[service]]\nname = \"a\"\nbinary = \"x\"\nrealtime_priority = 100", "service[0].realtime_priority"),
        ("[[service]]\nname = \"a\"\nbinary = \"x\"\nrealtime_priority = -1", "realtime_priority"),
        ("[[service]]\nname = \"a\"\nbinary = \"x\"\nenv = { SKYMESH_REALTIME_PRIORITY = \"20\" }", "SKYMESH_REALTIME_PRIORITY"),
        ("[[service]]\nname = \"a\"\nbinary = \"x\"\ncpu_affinity = [1, 4096]", "service[0].cpu_affinity"),
        ("[[service]]\nname = \"a\"\nbinary = \"x\"\ncpu_affinity = 1", "cpu_affinity"),
        ("[[service]]\nname = \"a\"\nbinary = \"x\"\nenv = { SKYMESH_CPU_AFFINITY = \"1\" }", "SKYMESH_CPU_AFFINITY"),
    ] {
        let e = parse(text).unwrap_err();
        assert!(e.to_string().contains(needle), "{text:?}: {e}");
    }
}

#[test]
fn service_overrides_merge_over_the_default_policy() {
    let s = parse(
        r#"
        [restart]
        budget = 3
        max_backoff_ms = 1000
        [[service]]
        name = "a"
        binary = "x"
        restart = { budget = 7, mode = "always" }
        [[service]]
        name = "b"
        binary = "x"
        enabled = false
        [[service]]
        name = "c"
        binary = "x"
        after = ["b"]
        "#,
    )
    .unwrap();
    let a = s.service("a").unwrap();
    assert_eq!(a.restart.max_restarts, 7);
    assert_eq!(a.restart.mode, RestartMode::Always);
    assert_eq!(a.restart.backoff_max, Duration::from_secs(1));
    let c = s.service("c").unwrap();
    assert_eq!(c.restart.max_restarts, 3);
    assert!(
        c.after.is_empty(),
        "a disabled dependency is not waited for"
    );
    assert!(s.service("b").is_none());
    assert_eq!(s.disabled, ["b"]);
}

#[test]
fn restart_keys_parse_into_the_policy() {
    let p = parse(
        "[restart]\ninitial_backoff_ms = 50\nmax_backoff_ms = 5000\njitter = 0.1\nbudget = 25\nbudget_window_s = 3600\nstable_after_s = 1\n[[service]]\nname = \"a\"\nbinary = \"x\"\n",
    )
    .unwrap()
    .services[0]
        .restart;
    assert_eq!(
        p,
        RestartPolicy {
            mode: RestartMode::OnFailure,
            backoff_initial: Duration::from_millis(50),
            backoff_max: Duration::from_secs(5),
            jitter: 0.1,
            stable_after: Duration::from_secs(1),
            max_restarts: 25,
            window: Duration::from_secs(3600),
        }
    );
}

#[test]
fn locate_files_finds_binaries_and_reports_missing_ones() {
    let dir = tempfile::tempdir().unwrap();
    let ok = parse(&format!(
        "[[service]]\nname = \"a\"\nbinary = \"sh\"\n[[service]]\nname = \"b\"\nbinary = \"/bin/sh\"\nconfig = \"{}\"",
        dir.path().join("b.toml").display()
    ))
    .unwrap();
    let e = ok.clone().locate_files(dir.path()).unwrap_err();
    assert!(e.to_string().contains("b.toml"), "{e}");
    std::fs::write(dir.path().join("b.toml"), "").unwrap();
    let s = ok.locate_files(dir.path()).unwrap();
    assert!(s.services[0].program.is_absolute(), "found in PATH");
    let e = parse("[[service]]\nname = \"a\"\nbinary = \"no-such-binary-xyz\"")
        .unwrap()
        .locate_files(dir.path())
        .unwrap_err();
    assert!(e.to_string().contains("no-such-binary-xyz"), "{e}");
}
