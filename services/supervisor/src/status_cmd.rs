//! `skymesh status`: asks the running supervisor's `/status` endpoint and prints a
//! table, or the JSON array with `--json`; its exit code is the mesh's
//! [`Health`](crate::health::Health): 0 every service runs, 1 some is degraded or
//! restarting, 2 a critical one is down or the supervisor does not answer.

use std::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use std::time::Duration;

use anyhow::{anyhow, bail, Context as _};
use bytes::Bytes;
use http_body_util::{BodyExt, Empty};
use hyper::header::HOST;
use hyper::{Request, StatusCode};
use hyper_util::rt::TokioIo;
use tokio::net::TcpStream;

use crate::health::{self, Health};
use crate::state::StatusEntry;
use crate::table;

/// How long `status` waits for the supervisor.
pub const TIMEOUT: Duration = Duration::from_secs(3);

/// The address to connect to for a configured listen address: a wildcard listen
/// address is reached through loopback.
pub fn connect_addr(listen: SocketAddr) -> SocketAddr {
    match listen.ip() {
        IpAddr::V4(ip) if ip.is_unspecified() => {
            SocketAddr::new(Ipv4Addr::LOCALHOST.into(), listen.port())
        }
        IpAddr::V6(ip) if ip.is_unspecified() => {
            SocketAddr::new(Ipv6Addr::LOCALHOST.into(), listen.port())
        }
        _ => listen,
    }
}

/// `GET path` on `addr` with a hyper HTTP/1 client; returns the status and body.
pub async fn http_get(addr: SocketAddr, path: &str) -> anyhow::Result<(StatusCode, String)> {
    let exchange = async {
        let stream = TcpStream::connect(addr)
            .await
            .with_context(|| format!("connecting to {addr}"))?;
        let (mut sender, conn) =
            hyper::client::conn::http1::handshake(TokioIo::new(stream)).await?;
        let driver = tokio::spawn(conn);
        let req = Request::get(path)
            .header(HOST, addr.to_string())
            .body(Empty::<Bytes>::new())?;
        let resp = sender.send_request(req).await?;
        let status = resp.status();
        let body = resp.into_body().collect().await?.to_bytes();
        drop(sender);
        driver.abort();
        let text =
            String::from_utf8(body.to_vec()).map_err(|_| anyhow!("response is not UTF-8"))?;
        anyhow::Ok((status, text))
    };
    tokio::time::timeout(TIMEOUT, exchange)
        .await
        .map_err(|_| anyhow!("no answer from {addr} within {TIMEOUT:?}"))?
}

/// The supervisor's `/status`, as typed entries.
pub async fn fetch(addr: SocketAddr) -> anyhow::Result<Vec<StatusEntry>> {
    let (status, body) = http_get(addr, "/status").await?;
    if status != StatusCode::OK {
        bail!("{addr}/status answered {status}");
    }
    serde_json::from_str(&body)
        .with_context(|| format!("{addr}/status is not a skymesh status array"))
}

/// Runs `skymesh status`: prints the table (or the JSON array) of the supervisor at
/// `addr` and returns the mesh's health. An error means the supervisor did not answer
/// (or not with a status array): exit 2.
pub async fn run(addr: SocketAddr, json: bool) -> anyhow::Result<Health> {
    let addr = connect_addr(addr);
    let rows = fetch(addr)
        .await
        .with_context(|| format!("no skymesh supervisor answers at http://{addr} (is `skymesh up` running? try --metrics ADDR)"))?;
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    } else if rows.is_empty() {
        println!("the supervisor at {addr} runs no services");
    } else {
        print!("{}", table::render(&rows));
        println!("{}", health::summary(&rows));
    }
    Ok(health::of(&rows))
}

/// The exit code of `skymesh status` for the outcome of [`run`].
pub fn exit_code(outcome: &anyhow::Result<Health>) -> u8 {
    match outcome {
        Ok(h) => h.exit_code(),
        Err(_) => Health::Critical.exit_code(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wildcard_listen_addresses_are_reached_through_loopback() {
        assert_eq!(
            connect_addr("0.0.0.0:9464".parse().unwrap()),
            "127.0.0.1:9464".parse().unwrap()
        );
        assert_eq!(
            connect_addr("[::]:1".parse().unwrap()),
            "[::1]:1".parse().unwrap()
        );
        assert_eq!(
            connect_addr("10.0.0.2:80".parse().unwrap()),
            "10.0.0.2:80".parse().unwrap()
        );
    }

    #[tokio::test]
    async fn nobody_listening_is_a_clear_error() {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = l.local_addr().unwrap();
        drop(l);
        let outcome = run(addr, false).await;
        assert_eq!(exit_code(&outcome), 2);
        let e = outcome.unwrap_err();
        assert!(
            format!("{e:#}").contains("no skymesh supervisor answers"),
            "{e:#}"
        );
    }

    /// A real HTTP server on the supervisor's handler: `run` (what `skymesh status`
    /// does) maps the mesh to 0/1/2, and `/healthz` agrees over the wire.
    #[tokio::test]
    async fn exit_code_follows_the_mesh_and_agrees_with_healthz() {
        use crate::state::{Mesh, Phase};
        use std::sync::Arc;
        use tokio_util::sync::CancellationToken;
        use tokio_util::task::TaskTracker;

        let mesh = Arc::new(Mesh::new(&[("a".into(), true), ("b".into(), false)], false));
        let vehicles = Arc::new(crate::vehicles::VehicleGauges::new(&[]));
        let console =
            crate::console::Console::new(mesh.clone(), vehicles, None, Default::default());
        let app = crate::http::App::new(
            mesh.clone(),
            crate::metrics::registry(mesh.clone()).unwrap(),
            Arc::new(console),
        );
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let stop = CancellationToken::new();
        let tracker = TaskTracker::new();
        let server = tokio::spawn(crate::http::serve(listener, app, stop.clone(), tracker));

        let check = |want_exit: u8, want_http: StatusCode| async move {
            let outcome = run(addr, true).await;
            assert_eq!(exit_code(&outcome), want_exit, "{outcome:?}");
            let (status, body) = http_get(addr, "/healthz").await.unwrap();
            assert_eq!(status, want_http, "{body}");
            let v: serde_json::Value = serde_json::from_str(&body).unwrap();
            assert_eq!(v["exit_code"], want_exit, "{body}");
        };

        mesh.set_phase(0, Phase::Running);
        mesh.set_phase(1, Phase::Running);
        check(0, StatusCode::OK).await;
        mesh.set_phase(1, Phase::Degraded);
        check(1, StatusCode::SERVICE_UNAVAILABLE).await;
        mesh.set_phase(1, Phase::Failed); // not critical
        check(1, StatusCode::SERVICE_UNAVAILABLE).await;
        mesh.set_phase(0, Phase::Backoff); // critical, restarting
        check(1, StatusCode::SERVICE_UNAVAILABLE).await;
        mesh.set_phase(0, Phase::Failed); // critical, down for good
        check(2, StatusCode::SERVICE_UNAVAILABLE).await;

        stop.cancel();
        server.await.unwrap();
        // Nobody answers any more.
        assert_eq!(exit_code(&run(addr, false).await), 2);
    }
}
