//! The supervisor's web console (services/supervisor/src/console/) in a real
//! browser: headless Chromium, driven through chromedriver's WebDriver HTTP API,
//! loads the page from a live mesh, shows the service rows, follows a vehicle's
//! altitude through a take-off, sends an emergency stop and a service restart with
//! the token, and the action endpoints refuse a missing or wrong token (403).
//!
//! Needs Debian's `chromium` and `chromium-driver`. Where they are missing the test
//! says "Chromium not available: …" and passes, unless SKYMESH_REQUIRE_CHROMIUM=1
//! (CI sets it) makes that a failure. SKYMESH_CONSOLE_SCREENSHOT=FILE also copies
//! the screenshot there.

use std::io::{Read as _, Write as _};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command as Process, Stdio};
use std::time::{Duration, Instant};

use serde_json::{json, Value};
use skymesh_e2e::ground::{runtime, Ground};
use skymesh_e2e::{free_port, Mesh, MeshOptions};

const TOKEN: &str = "e2e-console-token-0123456789";
const STARTUP: Duration = Duration::from_secs(30);
/// Generous: a take-off to 10 m takes about 10 s on an idle machine.
const FLIGHT: Duration = Duration::from_secs(90);
/// For the page to show what the supervisor knows (it polls once a second).
const PAGE: Duration = Duration::from_secs(30);

const CHROMIUM: [&str; 2] = ["/usr/bin/chromium", "/usr/bin/chromium-browser"];
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

// ---- a minimal HTTP/1.1 client (chromedriver and the supervisor) ------------

/// Sends `method path` with an optional JSON body and extra headers; returns the
/// status and the body.
fn http(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: Option<&Value>,
) -> std::io::Result<(u16, String)> {
    let body = body.map(|b| b.to_string()).unwrap_or_default();
    // HTTP/1.1 (chromedriver refuses 1.0), one request per connection.
    let mut req = format!("{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n");
    for (k, v) in headers {
        req.push_str(&format!("{k}: {v}\r\n"));
    }
    if !body.is_empty() || method == "POST" {
        req.push_str(&format!(
            "Content-Type: application/json\r\nContent-Length: {}\r\n",
            body.len()
        ));
    }
    req.push_str("\r\n");
    req.push_str(&body);
    raw(addr, req.as_bytes())
}

/// Writes `request` as is and reads the answer: by its Content-Length, to the
/// last chunk, or to the end of the connection (chromedriver keeps connections
/// open whatever the request says).
fn raw(addr: SocketAddr, request: &[u8]) -> std::io::Result<(u16, String)> {
    let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(5))?;
    // Creating a browser session can take a while on a loaded machine.
    s.set_read_timeout(Some(Duration::from_secs(120)))?;
    s.write_all(request)?;
    let mut resp = Vec::new();
    let mut buf = [0u8; 16384];
    let complete = |resp: &[u8]| -> bool {
        let Some(end) = resp.windows(4).position(|w| w == b"\r\n\r\n") else {
            return false;
        };
        let head = String::from_utf8_lossy(&resp[..end]).to_ascii_lowercase();
        let body = &resp[end + 4..];
        if let Some(len) = head
            .lines()
            .find_map(|l| l.strip_prefix("content-length:"))
            .and_then(|v| v.trim().parse::<usize>().ok())
        {
            return body.len() >= len;
        }
        head.contains("transfer-encoding: chunked") && body.ends_with(b"0\r\n\r\n")
    };
    loop {
        let n = s.read(&mut buf)?;
        if n == 0 {
            break;
        }
        resp.extend_from_slice(&buf[..n]);
        if complete(&resp) {
            break;
        }
    }
    let text = String::from_utf8_lossy(&resp).to_string();
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let chunked = head
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked");
    Ok((
        status,
        if chunked {
            unchunk(body)
        } else {
            body.to_string()
        },
    ))
}

fn unchunk(mut body: &str) -> String {
    let mut out = String::new();
    while let Some((size, rest)) = body.split_once("\r\n") {
        let n = usize::from_str_radix(size.trim(), 16).unwrap_or(0);
        if n == 0 || rest.len() < n {
            break;
        }
        out.push_str(&rest[..n]);
        body = rest[n..].trim_start_matches("\r\n");
    }
    out
}

// ---- WebDriver ---------------------------------------------------------------

/// chromedriver and one browser session; both end on drop.
struct Browser {
    driver: Child,
    addr: SocketAddr,
    session: String,
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = http(
            self.addr,
            "DELETE",
            &format!("/session/{}", self.session),
            &[],
            None,
        );
        let _ = self.driver.kill();
        let _ = self.driver.wait();
    }
}

const ELEMENT: &str = "element-6066-11e4-a52e-4f735466cecf";

impl Browser {
    /// Starts chromedriver on a free port and a headless Chromium session whose
    /// profile lives in `dir`.
    fn start(chromium: &Path, dir: &Path) -> Browser {
        let port = free_port();
        let log = std::fs::File::create(dir.join("chromedriver.log")).unwrap();
        let driver = Process::new(CHROMEDRIVER)
            .arg(format!("--port={port}"))
            .stdout(Stdio::from(log.try_clone().unwrap()))
            .stderr(Stdio::from(log))
            .spawn()
            .expect("starting chromedriver");
        let addr = SocketAddr::from(([127, 0, 0, 1], port));
        let mut b = Browser {
            driver,
            addr,
            session: String::new(),
        };
        // Ready when its /status says so.
        let deadline = Instant::now() + STARTUP;
        loop {
            let ready = http(addr, "GET", "/status", &[], None)
                .ok()
                .and_then(|(_, body)| serde_json::from_str::<Value>(&body).ok())
                .is_some_and(|v| v["value"]["ready"] == true);
            if ready {
                break;
            }
            assert!(
                Instant::now() < deadline,
                "chromedriver not ready within {STARTUP:?}: {}",
                std::fs::read_to_string(dir.join("chromedriver.log")).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(100));
        }
        let profile = dir.join("chromium-profile");
        // The machine may have no network: without these, Chromium keeps trying
        // to reach Google's services and floods the log with refused connections.
        let args = json!([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--window-size=1400,1700",
            format!("--user-data-dir={}", profile.display()),
        ]);
        let caps = json!({"capabilities": {"alwaysMatch": {
            "browserName": "chrome",
            "goog:chromeOptions": {"binary": chromium.display().to_string(), "args": args},
        }}});
        let v = b.call("POST", "/session", Some(&caps));
        b.session = v["sessionId"]
            .as_str()
            .unwrap_or_else(|| panic!("no session id in {v}"))
            .to_string();
        b
    }

    /// One WebDriver command; returns its `value`, panicking on a WebDriver error.
    fn call(&self, method: &str, path: &str, body: Option<&Value>) -> Value {
        let (status, text) = http(self.addr, method, path, &[], body)
            .unwrap_or_else(|e| panic!("WebDriver {method} {path}: {e}"));
        let v: Value = serde_json::from_str(&text)
            .unwrap_or_else(|e| panic!("WebDriver {method} {path}: {e}: {text}"));
        assert_eq!(status, 200, "WebDriver {method} {path}: {v}");
        v["value"].clone()
    }

    fn session_call(&self, method: &str, path: &str, body: Option<&Value>) -> Value {
        self.call(method, &format!("/session/{}{path}", self.session), body)
    }

    fn goto(&self, url: &str) {
        self.session_call("POST", "/url", Some(&json!({ "url": url })));
    }

    /// Runs `script` (a function body; `return` its result) in the page.
    fn js(&self, script: &str) -> Value {
        self.session_call(
            "POST",
            "/execute/sync",
            Some(&json!({ "script": script, "args": [] })),
        )
    }

    fn element(&self, css: &str) -> String {
        let v = self.session_call(
            "POST",
            "/element",
            Some(&json!({ "using": "css selector", "value": css })),
        );
        v[ELEMENT]
            .as_str()
            .unwrap_or_else(|| panic!("no element {css}: {v}"))
            .to_string()
    }

    fn click(&self, css: &str) {
        let id = self.element(css);
        self.session_call("POST", &format!("/element/{id}/click"), Some(&json!({})));
    }

    fn type_into(&self, css: &str, text: &str) {
        let id = self.element(css);
        self.session_call(
            "POST",
            &format!("/element/{id}/value"),
            Some(&json!({ "text": text })),
        );
    }

    fn screenshot(&self) -> Vec<u8> {
        let v = self.session_call("GET", "/screenshot", None);
        base64_decode(v.as_str().expect("screenshot as base64"))
    }

    /// Evaluates `script` until `done` accepts its value (the page redraws once a
    /// second); panics after `within` with the last value.
    fn wait(
        &self,
        within: Duration,
        what: &str,
        script: &str,
        done: impl Fn(&Value) -> bool,
    ) -> Value {
        let deadline = Instant::now() + within;
        loop {
            let v = self.js(script);
            if done(&v) {
                return v;
            }
            assert!(
                Instant::now() < deadline,
                "{what}: not seen within {within:?}; last: {v}"
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

fn base64_decode(text: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => Some(c - b'A'),
        b'a'..=b'z' => Some(c - b'a' + 26),
        b'0'..=b'9' => Some(c - b'0' + 52),
        b'+' => Some(62),
        b'/' => Some(63),
        _ => None,
    };
    let mut out = Vec::with_capacity(text.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0);
    for v in text.bytes().filter_map(value) {
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    out
}

/// Chromium and chromedriver, or why not.
fn chromium() -> Result<PathBuf, String> {
    let browser = CHROMIUM
        .iter()
        .map(PathBuf::from)
        .find(|p| p.is_file())
        .ok_or_else(|| {
            format!("none of {CHROMIUM:?} exists (apt-get install chromium chromium-driver)")
        })?;
    if !Path::new(CHROMEDRIVER).is_file() {
        return Err(format!(
            "{CHROMEDRIVER} does not exist (apt-get install chromium-driver)"
        ));
    }
    Ok(browser)
}

// ---- the mesh side -------------------------------------------------------------

const ALTITUDE: &str = "const e = document.querySelector('#vehicle-1 [data-f=alt]'); \
     return e && e.dataset.value !== '' && e.dataset.value !== undefined ? Number(e.dataset.value) : null;";

#[test]
fn the_console_shows_the_mesh_in_a_real_browser_and_its_actions_need_the_token() {
    let chromium = match chromium() {
        Ok(p) => p,
        Err(why) => {
            assert!(
                std::env::var("SKYMESH_REQUIRE_CHROMIUM").as_deref() != Ok("1"),
                "Chromium not available: {why} (SKYMESH_REQUIRE_CHROMIUM=1)"
            );
            println!("Chromium not available: {why}; skipping the browser test");
            return;
        }
    };
    let mut mesh = Mesh::start(MeshOptions {
        supervisor_extra: format!("console_token = \"{TOKEN}\"\n"),
        ..MeshOptions::default()
    })
    .unwrap();
    let addr = mesh.metrics_addr();
    let browser = Browser::start(&chromium, mesh.dir.path());
    browser.goto(&format!("http://{addr}/"));

    // Every service has its row, and they run.
    let names: Vec<String> = mesh
        .status()
        .unwrap()
        .iter()
        .filter_map(|s| s["name"].as_str().map(str::to_string))
        .collect();
    assert_eq!(names, ["vehicle-sim", "autopilot-link"]);
    let rows = browser.wait(
        STARTUP,
        "every service running in the page",
        "return [...document.querySelectorAll('#services tbody tr')].map(r => [r.dataset.name, r.querySelector('[data-f=state]').textContent]);",
        |v| {
            v.as_array().is_some_and(|rows| {
                rows.len() == 2 && rows.iter().all(|r| r[1] == "running")
            })
        },
    );
    println!("service rows: {rows}");
    // The token field and the actions are there, since a token is configured.
    assert_eq!(
        browser.js("return document.querySelector('#auth').hidden;"),
        false
    );

    let rt = runtime();
    let mut operator = rt.block_on(async { Ground::new(&mesh, "e2e-console") });

    // On the ground: the page shows a position and an altitude near 0.
    let alt0 = browser.wait(
        PAGE,
        "an altitude on the ground",
        ALTITUDE,
        Value::is_number,
    );
    let alt0 = alt0.as_f64().unwrap();
    assert!(alt0.abs() < 1.0, "on the ground: {alt0} m");
    rt.block_on(operator.take_off(10.0));
    // The operator keeps its flight authority while the take-off flies (a grab
    // about every second), as a source flying a position target must.
    let deadline = Instant::now() + FLIGHT;
    let alt = loop {
        let alt = browser.js(ALTITUDE).as_f64().unwrap_or(f64::NAN);
        if alt > 5.0 {
            break alt;
        }
        assert!(
            Instant::now() < deadline,
            "the page's altitude never passed 5 m (last {alt})\n{}",
            mesh.output()
        );
        operator.keep_authority();
        std::thread::sleep(Duration::from_millis(250));
    };
    println!("altitude in the page: {alt0:.2} m on the ground, {alt:.2} m in the take-off");
    let card = browser.js("const c = document.querySelector('#vehicle-1'); \
         return { armed: c.querySelector('[data-f=armed]').textContent, \
                  mode: c.querySelector('[data-f=mode]').textContent, \
                  points: Number(c.querySelector('canvas').dataset.points), \
                  decisions: c.querySelector('.decisions').textContent };");
    assert_eq!(card["armed"], "ARMED", "{card}");
    assert_eq!(card["mode"], "guided", "{card}");
    assert!(
        card["points"].as_u64().unwrap() >= 2,
        "the plot has a history: {card}"
    );
    assert!(
        card["decisions"].as_str().unwrap().contains("takeoff"),
        "the arbiter's decisions list the take-off: {card}"
    );

    // The emergency stop, from the page with the token, through the arbiter.
    browser.type_into("#token", TOKEN);
    browser.click("#vehicle-1 button[data-act=emergency-stop]");
    let stopped = browser.wait(
        PAGE,
        "the emergency stop shown",
        "const c = document.querySelector('#vehicle-1'); \
         return { badge: !c.querySelector('[data-f=emergency]').hidden, \
                  events: c.querySelector('.events').dataset.kinds || '', \
                  authority: c.querySelector('[data-f=authority]').dataset.flight, \
                  message: document.querySelector('#message').textContent };",
        |v| {
            let has = |k: &str, s: &str| v[k].as_str().unwrap_or("").contains(s);
            // The badge and event from the bus, the answer from the arbiter's ack.
            v["badge"] == true
                && has("events", "emergency_stop")
                && (has("message", "emergency_stop accepted") || has("message", "refused"))
        },
    );
    println!("after the emergency stop: {stopped}");
    assert!(
        stopped["message"]
            .as_str()
            .unwrap()
            .contains("emergency_stop accepted"),
        "{stopped}"
    );
    assert_eq!(stopped["authority"], "safety", "{stopped}");

    // A restart from the page: the restart count rises and the service runs again.
    let old_pid = mesh.wait_running("autopilot-link", STARTUP).unwrap();
    let before = mesh.service("autopilot-link").unwrap()["restarts"]
        .as_u64()
        .unwrap();
    browser.click("button[data-restart=autopilot-link]");
    let after = browser.wait(
        STARTUP,
        "autopilot-link restarted in the page",
        "const r = document.querySelector('#svc-autopilot-link [data-f=restarts]'); \
         const s = document.querySelector('#svc-autopilot-link [data-f=state]'); \
         return [Number(r.dataset.value), s.textContent];",
        |v| v[0].as_u64().is_some_and(|n| n > before) && v[1] == "running",
    );
    println!("autopilot-link after the restart: {after}");
    let new_pid = mesh
        .wait_restarted("autopilot-link", old_pid, STARTUP)
        .unwrap();
    assert_ne!(new_pid, old_pid);

    let png = browser.screenshot();
    assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"), "a PNG screenshot");
    let shot = mesh.dir.path().join("console.png");
    std::fs::write(&shot, &png).unwrap();
    println!("screenshot: {} ({} bytes)", shot.display(), png.len());
    if let Ok(copy) = std::env::var("SKYMESH_CONSOLE_SCREENSHOT") {
        std::fs::write(&copy, &png).unwrap();
    }

    // Without the token, or with a wrong one, the actions are refused.
    let restarts = mesh.service("autopilot-link").unwrap()["restarts"].clone();
    let wrong = "Bearer wrong-token-but-long-enough";
    for path in [
        "/api/services/autopilot-link/restart",
        "/api/vehicles/1/emergency-stop",
        "/api/vehicles/1/release-emergency",
    ] {
        for headers in [vec![], vec![("Authorization", wrong)]] {
            let (status, body) = http(addr, "POST", path, &headers, None).unwrap();
            assert_eq!(status, 403, "POST {path} {headers:?}: {body}");
        }
    }
    assert_eq!(
        mesh.service("autopilot-link").unwrap()["restarts"],
        restarts
    );

    // Malformed requests: a 4xx each, and the supervisor keeps answering.
    let bearer = format!("Bearer {TOKEN}");
    let auth = [("Authorization", bearer.as_str())];
    for (method, path, want) in [
        ("GET", "/api/vehicles/1/emergency-stop", 405),
        ("POST", "/api/vehicles/9/emergency-stop", 404),
        ("POST", "/api/vehicles/x/emergency-stop", 404),
        ("POST", "/api/services/no-such/restart", 404),
        ("GET", "/api/nothing", 404),
    ] {
        let (status, body) = http(addr, method, path, &auth, None).unwrap();
        assert_eq!(status, want, "{method} {path}: {body}");
    }
    let (status, _) = raw(addr, b"NOT-HTTP\r\n\r\n").unwrap();
    assert_eq!(status, 400, "a request line hyper cannot parse");
    let (status, _) = raw(addr, b"GET / HTTP/1.1\r\nHost\r\n\r\n").unwrap();
    assert_eq!(status, 400, "a header without a colon");
    assert!(mesh.http_get("/status").is_ok(), "{}", mesh.output());

    // The operator's stop is released from the page too.
    browser.click("#vehicle-1 button[data-act=release-emergency]");
    browser.wait(
        PAGE,
        "the emergency stop released",
        "return document.querySelector('#vehicle-1 [data-f=emergency]').hidden;",
        |v| *v == true,
    );
    drop(browser);
    drop(operator);
}
