//! Resources another program (or the system) holds: a gateway's port already in use
//! and a `/dev/shm` without room. Both must end in a clear error and a distinct exit
//! code the supervisor retries with growing backoff, never a tight crash loop or a
//! SIGBUS.

mod solo_common;

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use skymesh_e2e::{binary, repo_root, MeshOptions};
use skymesh_runtime::exit;
use solo_common::{app, runtime, start_solo_mesh};

/// Seconds since midnight (UTC) of a log line's leading RFC 3339 timestamp.
fn seconds_of_day(line: &str) -> Option<f64> {
    let time = line.split_whitespace().next()?.split('T').nth(1)?;
    let time = time.trim_end_matches('Z');
    let mut parts = time.split(':');
    let h: f64 = parts.next()?.parse().ok()?;
    let m: f64 = parts.next()?.parse().ok()?;
    let s: f64 = parts.next()?.parse().ok()?;
    Some(h * 3600.0 + m * 60.0 + s)
}

/// The value of `key=` in a text log line.
fn field<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    let at = line.find(&format!(" {key}="))? + key.len() + 2;
    line[at..].split_whitespace().next()
}

/// The supervisor's "restarting after backoff" lines for `service` in `log`:
/// (seconds of day, delay in ms).
fn backoffs(log: &str, service: &str) -> Vec<(f64, u64)> {
    log.lines()
        .filter(|l| l.contains("restarting after backoff"))
        .filter(|l| field(l, "service") == Some(service))
        .filter_map(|l| Some((seconds_of_day(l)?, field(l, "delay_ms")?.parse().ok()?)))
        .collect()
}

/// Checks that the restarts were decided with doubling delays, starting at
/// `initial_ms` (the policy has no jitter), and that each restart attempt came no
/// sooner than the delay before it (a lower bound only: no tight crash loop).
fn assert_growing_backoff(spaced: &[(f64, u64)], initial_ms: u64, log: &str) {
    for (i, (_, delay)) in spaced.iter().enumerate() {
        assert_eq!(
            *delay,
            initial_ms << i,
            "restart {} was not backed off by {} ms: {spaced:?}\n{log}",
            i + 1,
            initial_ms << i
        );
    }
    for pair in spaced.windows(2) {
        let gap = (pair[1].0 - pair[0].0).rem_euclid(86_400.0);
        assert!(
            gap * 1000.0 >= pair[0].1 as f64,
            "restarts {gap:.3} s apart, less than the {} ms backoff: {spaced:?}\n{log}",
            pair[0].1
        );
    }
}

/// Solo-gateway's port taken by another program: every restart fails with "address
/// already in use" naming the address and exit code 75 (not 64: it clears by itself),
/// the supervisor retries with doubling backoff, and once the port is free again the
/// gateway comes back and serves an app.
#[test]
fn port_in_use_is_a_clear_error_retried_with_backoff() {
    const INITIAL_MS: u64 = 200;
    let mut mesh = start_solo_mesh(MeshOptions {
        restart: vec![(
            "solo-gateway".to_string(),
            format!(
                "{{ initial_backoff_ms = {INITIAL_MS}, max_backoff_ms = 5000, jitter = 0.0, budget = 20, stable_after_s = 30 }}"
            ),
        )],
        ..Default::default()
    });
    let addr = format!("127.0.0.1:{}", mesh.solo_port);

    // Kill the gateway and take its port before the supervisor restarts it (200 ms).
    let old = mesh.kill_service("solo-gateway").unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    let holder = loop {
        match TcpListener::bind(&addr) {
            Ok(l) => break l,
            Err(_) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(5)),
            Err(e) => panic!("cannot take {addr} after killing the gateway: {e}"),
        }
    };

    // Three failed restarts: 200, 400, 800 ms (the kill itself was the first failure).
    let spaced = mesh
        .wait_for(Duration::from_secs(15), "three backed-off restarts", |m| {
            let b = backoffs(&m.output(), "solo-gateway");
            (b.len() >= 4).then_some(b)
        })
        .unwrap_or_else(|e| panic!("{e:#}\n{}", mesh.output()));
    let log = mesh.output();
    assert_growing_backoff(&spaced[..4], INITIAL_MS, &log);

    // The gateway's own error names the address and the cause, at error level...
    let clear = "address already in use";
    let error_line = log
        .lines()
        .find(|l| l.contains(" ERROR ") && l.contains(clear) && l.contains(&addr))
        .unwrap_or_else(|| panic!("no error line naming {addr} and `{clear}`\n{log}"));
    assert!(
        error_line.contains("Address already in use"),
        "the OS cause is kept: {error_line}"
    );
    // ...and the supervisor saw the distinct exit code (restarted, unlike 64).
    let code = format!("code={}", exit::ADDR_IN_USE);
    assert!(
        log.lines().any(|l| l.contains("service=solo-gateway")
            && l.contains(" exited")
            && l.contains(&code)),
        "no `exited` line with {code}\n{log}"
    );
    assert_ne!(exit::ADDR_IN_USE, exit::CONFIG);
    assert_ne!(
        mesh.service("solo-gateway").unwrap()["state"],
        "config-error"
    );

    // The other program goes away: the gateway comes back and serves an app.
    drop(holder);
    let new = mesh
        .wait_restarted("solo-gateway", old, Duration::from_secs(15))
        .unwrap_or_else(|e| panic!("{e:#}\n{}", mesh.output()));
    assert_ne!(new, old);
    runtime().block_on(async {
        // `app` connects and waits for the current shot the engine announces.
        let _app = app(&mesh).await;
    });
}

/// How a command run under a private, tiny `/dev/shm` ended (exit status, stderr);
/// killed and reported as a failure if it still runs after 20 s.
fn in_tiny_shm(
    size: &str,
    program: &Path,
    args: &[&str],
    env: &[(&str, String)],
    dir: &Path,
) -> (std::process::ExitStatus, String) {
    let err_path = dir.join(format!("tiny-shm-{size}.stderr"));
    let mut cmd = Command::new("unshare");
    cmd.args(["--mount", "--propagation", "private", "--", "sh", "-c"])
        .arg(format!(
            "mount -t tmpfs -o size={size} tmpfs /dev/shm && exec \"$@\""
        ))
        .arg("sh")
        .arg(program)
        .args(args)
        .env("NO_COLOR", "1")
        .env("RUST_LOG", "info")
        .env_remove("NOTIFY_SOCKET")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&err_path).unwrap());
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().expect("running unshare");
    let deadline = Instant::now() + Duration::from_secs(20);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "{} still runs in a {size} /dev/shm after 20 s\n{}",
                program.display(),
                std::fs::read_to_string(&err_path).unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    (
        status,
        std::fs::read_to_string(&err_path).unwrap_or_default(),
    )
}

/// `None` if this machine lets a test mount a private tmpfs on `/dev/shm`, else why not.
fn private_shm_unavailable() -> Option<String> {
    match Command::new("unshare")
        .args(["--mount", "--propagation", "private", "--", "sh", "-c"])
        .arg("mount -t tmpfs -o size=1m tmpfs /dev/shm")
        .output()
    {
        Err(e) => Some(format!("cannot run unshare: {e}")),
        Ok(o) if !o.status.success() => Some(format!(
            "unshare/mount not permitted ({}): {}",
            o.status,
            String::from_utf8_lossy(&o.stderr).trim()
        )),
        Ok(_) => None,
    }
}

/// A temp dir with an iceoryx2 config whose root path is inside it (so nothing of
/// these runs is left in the shared `/tmp/iceoryx2`), and a unique domain.
fn private_ipc(dir: &Path) -> (PathBuf, String) {
    let text = std::fs::read_to_string(repo_root().join("deploy/iceoryx2.toml")).unwrap();
    let root = dir.join("iox");
    std::fs::create_dir_all(&root).unwrap();
    let text = text.replace(
        "root-path = \"/tmp/iceoryx2/\"",
        &format!("root-path = \"{}/\"", root.display()),
    );
    assert!(
        text.contains(&root.display().to_string()),
        "root-path key moved"
    );
    let path = dir.join("iceoryx2.toml");
    std::fs::write(&path, text).unwrap();
    let domain = format!("res{}", std::process::id());
    (path, domain)
}

/// A `/dev/shm` with 2 MiB: a service refuses to start with "shared memory /dev/shm
/// is full" and exit code 73 instead of dying of SIGBUS when iceoryx2 touches pages
/// that cannot be backed; under `skymesh up` it is retried with doubling backoff.
#[test]
fn full_dev_shm_is_a_clear_error_retried_with_backoff() {
    if let Some(why) = private_shm_unavailable() {
        eprintln!("skipping: {why}");
        return;
    }
    let dir = tempfile::Builder::new()
        .prefix("skymesh-res-")
        .tempdir()
        .unwrap();
    let (ipc_config, domain) = private_ipc(dir.path());
    let sim_config = dir.path().join("vehicle-sim.toml");
    std::fs::write(&sim_config, "endpoint = \"tcp:127.0.0.1:0\"\n").unwrap();
    let env = [
        ("SKYMESH_DOMAIN", domain.clone()),
        ("SKYMESH_IPC_CONFIG", ipc_config.display().to_string()),
    ];

    // One service alone, with 256 KiB: without the check iceoryx2 dies of SIGBUS
    // there (tmpfs accepts the sparse segment, then cannot back a page).
    let sim = binary("skymesh-vehicle-sim");
    let (status, stderr) = in_tiny_shm(
        "256k",
        &sim,
        &["--config", sim_config.to_str().unwrap()],
        &env,
        dir.path(),
    );
    assert_eq!(
        status.code(),
        Some(i32::from(exit::SHM_FULL)),
        "{status:?} (a SIGBUS shows as no code)\n{stderr}"
    );
    assert!(
        stderr.lines().any(|l| l.contains(" ERROR ")
            && l.contains("shared memory /dev/shm is full: ")
            && l.contains("bytes free of ")
            && l.contains("need at least ")),
        "{stderr}"
    );

    // Under the supervisor: retried with doubling backoff until the budget is spent.
    const INITIAL_MS: u64 = 100;
    let mesh_config = dir.path().join("skymesh.toml");
    std::fs::write(
        &mesh_config,
        format!(
            "[supervisor]\n\
             metrics = \"127.0.0.1:0\"\n\
             ipc_config = \"{ipc}\"\n\
             [restart]\n\
             initial_backoff_ms = {INITIAL_MS}\n\
             max_backoff_ms = 5000\n\
             jitter = 0.0\n\
             budget = 3\n\
             budget_window_s = 60\n\
             [[service]]\n\
             name = \"vehicle-sim\"\n\
             binary = \"{sim}\"\n\
             config = \"{cfg}\"\n",
            ipc = ipc_config.display(),
            sim = sim.display(),
            cfg = sim_config.display(),
        ),
    )
    .unwrap();
    let log_path = dir.path().join("up.log");
    let log_file = std::fs::File::create(&log_path).unwrap();
    let mut up = Command::new("unshare")
        .args(["--mount", "--propagation", "private", "--", "sh", "-c"])
        .arg("mount -t tmpfs -o size=2m tmpfs /dev/shm && exec \"$@\"")
        .arg("sh")
        .arg(binary("skymesh"))
        .args(["up", "--no-table", "--config"])
        .arg(&mesh_config)
        .env("SKYMESH_DOMAIN", &domain)
        .env("RUST_LOG", "info")
        .env_remove("NOTIFY_SOCKET")
        .stdin(Stdio::null())
        .stdout(log_file.try_clone().unwrap())
        .stderr(log_file)
        .spawn()
        .unwrap();
    let read_log = || std::fs::read_to_string(&log_path).unwrap_or_default();
    let deadline = Instant::now() + Duration::from_secs(20);
    let log = loop {
        let log = read_log();
        if log.contains("restart budget")
            || log
                .lines()
                .filter(|l| l.contains("restarting after backoff"))
                .count()
                >= 3
        {
            break log;
        }
        if let Ok(Some(status)) = up.try_wait() {
            panic!("skymesh up exited ({status}) before the restarts\n{log}");
        }
        if Instant::now() > deadline {
            let _ = up.kill();
            let _ = up.wait();
            panic!("no three backed-off restarts within 20 s\n{log}");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(up.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    );
    let stopped = up.wait().unwrap();
    let log = format!(
        "{log}\n--- after SIGTERM ---\n{}",
        read_log().get(log.len()..).unwrap_or("")
    );
    let spaced = backoffs(&log, "vehicle-sim");
    assert!(spaced.len() >= 3, "{spaced:?}\n{log}");
    assert_growing_backoff(&spaced[..3], INITIAL_MS, &log);
    let code = format!("code={}", exit::SHM_FULL);
    assert!(
        log.lines()
            .filter(|l| l.contains("service=vehicle-sim") && l.contains(" exited"))
            .all(|l| l.contains(&code))
            && log.contains(&code),
        "every run must end with {code}, never a signal\n{log}"
    );
    assert!(!log.contains("killed by signal"), "{log}");
    assert!(stopped.code().is_some(), "skymesh up: {stopped:?}\n{log}");
}
