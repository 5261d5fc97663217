//! The console's routes, token and peer checks, without a bus.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use http_body_util::BodyExt as _;
use hyper::header::{AUTHORIZATION, CONTENT_TYPE};
use hyper::{Method, Request, StatusCode};

use super::*;
use crate::state::{Mesh, Phase};
use crate::supervise::RestartRequests;
use crate::vehicles::VehicleGauges;

const TOKEN: &str = "test-token-0123456789";

struct Fixture {
    console: Console,
    mesh: Arc<Mesh>,
    restarts: Arc<RestartRequests>,
}

fn fixture(token: Option<&str>, remote: bool, monitor_only: bool) -> Fixture {
    let mesh = Arc::new(Mesh::new(
        &[
            ("vehicle-sim".into(), true),
            ("autopilot-link".into(), true),
        ],
        monitor_only,
    ));
    let restarts = Arc::new(RestartRequests::new(2));
    let settings =
        ConsoleSettings::from_raw(token, None, remote, std::path::Path::new("/")).unwrap();
    let console = Console::new(
        mesh.clone(),
        Arc::new(VehicleGauges::new(&[1])),
        (!monitor_only).then(|| restarts.clone()),
        settings,
    );
    Fixture {
        console,
        mesh,
        restarts,
    }
}

fn block_on<F: std::future::Future>(f: F) -> F::Output {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
        .block_on(f)
}

const LOCAL: &str = "127.0.0.1:40000";

fn call(c: &Console, method: Method, path: &str, auth: Option<&str>, peer: &str) -> Reply {
    let mut b = Request::builder().method(method).uri(path);
    if let Some(a) = auth {
        b = b.header(AUTHORIZATION, a);
    }
    let peer: SocketAddr = peer.parse().unwrap();
    block_on(c.handle(&b.body(()).unwrap(), peer))
}

fn body(r: Reply) -> String {
    let bytes = block_on(r.into_body().collect()).unwrap().to_bytes();
    String::from_utf8(bytes.to_vec()).unwrap()
}

fn json_body(r: Reply) -> Value {
    serde_json::from_str(&body(r)).unwrap()
}

#[test]
fn the_page_and_its_files_are_served_with_their_types() {
    let f = fixture(None, false, false);
    for (path, ty, needle) in [
        ("/", "text/html; charset=utf-8", "/console.js"),
        ("/console.css", "text/css; charset=utf-8", ".vehicle"),
        ("/console.js", "text/javascript; charset=utf-8", "/api/mesh"),
    ] {
        let r = call(&f.console, Method::GET, path, None, LOCAL);
        assert_eq!(r.status(), StatusCode::OK, "{path}");
        assert_eq!(r.headers()[CONTENT_TYPE], ty);
        assert!(r.headers()["content-security-policy"]
            .to_str()
            .unwrap()
            .contains("default-src 'none'"));
        assert!(body(r).contains(needle), "{path}");
    }
    // Nothing loaded from elsewhere.
    for a in assets::ASSETS {
        assert!(
            !a.body.contains("http://") && !a.body.contains("https://"),
            "{}",
            a.path
        );
    }
    let r = call(&f.console, Method::HEAD, "/", None, LOCAL);
    assert_eq!(r.status(), StatusCode::OK);
    let r = call(&f.console, Method::PUT, "/", None, LOCAL);
    assert_eq!(r.status(), StatusCode::METHOD_NOT_ALLOWED);
}

#[test]
fn the_documents_describe_services_and_vehicles() {
    let f = fixture(None, false, false);
    f.mesh.update(1, |e| {
        e.phase = Phase::Running;
        e.pid = Some(std::process::id());
        e.restarts = 2;
    });
    // Two reads of our own process: the second has a CPU figure once time passed.
    let _ = f.console.mesh_doc();
    let v = json_body(call(&f.console, Method::GET, "/api/mesh", None, LOCAL));
    assert_eq!(v["actions"], false);
    assert_eq!(v["restart_action"], false);
    let link = &v["services"][1];
    assert_eq!(link["name"], "autopilot-link");
    assert_eq!(link["state"], "running");
    assert_eq!(link["restarts"], 2);
    assert!(link["memory_bytes"].as_u64().unwrap() > 0, "{link}");
    assert_eq!(v["services"][0]["pid"], Value::Null);
    let v = json_body(call(&f.console, Method::GET, "/api/vehicles", None, LOCAL));
    assert_eq!(v["vehicles"][0]["id"], 1);
    assert_eq!(v["vehicles"][0]["link_up"], false);
    let r = call(&f.console, Method::POST, "/api/mesh", None, LOCAL);
    assert_eq!(r.status(), StatusCode::METHOD_NOT_ALLOWED);
}

#[test]
fn without_a_token_the_actions_do_not_exist() {
    let f = fixture(None, false, false);
    for path in [
        "/api/services/autopilot-link/restart",
        "/api/vehicles/1/emergency-stop",
        "/api/vehicles/1/release-emergency",
    ] {
        for auth in [
            None,
            Some("Bearer anything-at-all-long-enough"),
            Some(&*format!("Bearer {TOKEN}")),
        ] {
            let r = call(&f.console, Method::POST, path, auth, LOCAL);
            assert_eq!(r.status(), StatusCode::FORBIDDEN, "{path} {auth:?}");
            assert!(json_body(r)["error"]
                .as_str()
                .unwrap()
                .contains("console_token"));
        }
    }
}

#[test]
fn actions_need_the_right_token() {
    let f = fixture(Some(TOKEN), false, false);
    let restart = "/api/services/autopilot-link/restart";
    let bearer = format!("Bearer {TOKEN}");
    for auth in [
        None,
        Some("Bearer wrong-token-0123456789"),
        Some("Bearer "),
        Some(TOKEN),
        Some("Basic dXNlcjpwYXNz"),
        Some(&*format!("Bearer {TOKEN}x")),
    ] {
        let r = call(&f.console, Method::POST, restart, auth, LOCAL);
        assert_eq!(r.status(), StatusCode::FORBIDDEN, "{auth:?}");
    }
    let v = json_body(call(&f.console, Method::GET, "/api/mesh", None, LOCAL));
    assert_eq!(
        (v["actions"].as_bool(), v["restart_action"].as_bool()),
        (Some(true), Some(true))
    );

    // Starting without a process yet: not now.
    let r = call(&f.console, Method::POST, restart, Some(&bearer), LOCAL);
    assert_eq!(r.status(), StatusCode::CONFLICT);
    f.mesh.update(1, |e| {
        e.phase = Phase::Running;
        e.pid = Some(1234);
    });
    let r = call(&f.console, Method::POST, restart, Some(&bearer), LOCAL);
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    assert_eq!(json_body(r)["restart"], "requested");
    // The supervision task of service 1 sees it.
    block_on(async {
        tokio::time::timeout(Duration::from_secs(5), f.restarts.requested(1))
            .await
            .expect("the request reached the service's slot");
    });

    let r = call(
        &f.console,
        Method::POST,
        "/api/services/nope/restart",
        Some(&bearer),
        LOCAL,
    );
    assert_eq!(r.status(), StatusCode::NOT_FOUND);
    // Not on the bus yet: the command cannot go out.
    let r = call(
        &f.console,
        Method::POST,
        "/api/vehicles/1/emergency-stop",
        Some(&bearer),
        LOCAL,
    );
    assert_eq!(r.status(), StatusCode::SERVICE_UNAVAILABLE);
    for bad in [
        "/api/vehicles/2/emergency-stop",
        "/api/vehicles/abc/emergency-stop",
        "/api/vehicles/256/emergency-stop",
        "/api/vehicles//emergency-stop",
    ] {
        let r = call(&f.console, Method::POST, bad, Some(&bearer), LOCAL);
        assert_eq!(r.status(), StatusCode::NOT_FOUND, "{bad}");
    }
}

#[test]
fn malformed_requests_get_a_4xx() {
    let f = fixture(Some(TOKEN), false, false);
    let bearer = format!("Bearer {TOKEN}");
    for (method, path, want) in [
        (
            Method::GET,
            "/api/services/autopilot-link/restart",
            StatusCode::METHOD_NOT_ALLOWED,
        ),
        (
            Method::DELETE,
            "/api/vehicles/1/emergency-stop",
            StatusCode::METHOD_NOT_ALLOWED,
        ),
        (Method::POST, "/api/", StatusCode::NOT_FOUND),
        (
            Method::POST,
            "/api/services/autopilot-link/restart/again",
            StatusCode::NOT_FOUND,
        ),
        (
            Method::POST,
            "/api/vehicles/1/self-destruct",
            StatusCode::NOT_FOUND,
        ),
        (Method::GET, "/api/nothing", StatusCode::NOT_FOUND),
    ] {
        let r = call(&f.console, method.clone(), path, Some(&bearer), LOCAL);
        assert_eq!(r.status(), want, "{method} {path}");
        assert!(json_body(r)["error"].is_string());
    }
}

#[test]
fn only_loopback_peers_unless_remote_is_allowed() {
    let f = fixture(Some(TOKEN), false, false);
    for peer in ["192.168.1.20:5000", "[2001:db8::1]:5000"] {
        let r = call(&f.console, Method::GET, "/", None, peer);
        assert_eq!(r.status(), StatusCode::FORBIDDEN, "{peer}");
    }
    for peer in ["[::1]:5000", "[::ffff:127.0.0.1]:5000", "127.0.0.9:1"] {
        let r = call(&f.console, Method::GET, "/api/mesh", None, peer);
        assert_eq!(r.status(), StatusCode::OK, "{peer}");
    }
    let f = fixture(Some(TOKEN), true, false);
    let r = call(&f.console, Method::GET, "/", None, "192.168.1.20:5000");
    assert_eq!(r.status(), StatusCode::OK);
}

#[test]
fn monitor_only_refuses_restarts() {
    let f = fixture(Some(TOKEN), false, true);
    f.mesh.update(0, |e| {
        e.phase = Phase::Running;
        e.pid = Some(1);
    });
    let bearer = format!("Bearer {TOKEN}");
    let r = call(
        &f.console,
        Method::POST,
        "/api/services/vehicle-sim/restart",
        Some(&bearer),
        LOCAL,
    );
    assert_eq!(r.status(), StatusCode::CONFLICT);
    assert!(json_body(r)["error"].as_str().unwrap().contains("systemd"));
    let v = json_body(call(&f.console, Method::GET, "/api/mesh", None, LOCAL));
    assert_eq!(
        (v["actions"].as_bool(), v["restart_action"].as_bool()),
        (Some(true), Some(false))
    );
}
