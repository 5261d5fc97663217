//! The supervisor's HTTP endpoint (hyper 1): `GET /metrics` (Prometheus text),
//! `GET /status` (JSON array of services) and `GET /healthz` (200 when every service
//! runs, else 503; a short JSON [`health::Report`]); the web console at `/`,
//! `/console.*` and `/api/…` ([`crate::console`]); 404 for anything else.
//!
//! Every 4xx answer is logged with the peer, method and path (a warning at most once
//! per 10 s per peer and status, the rest at debug), and so is a request hyper could
//! not parse (it answers those 400 itself).

use std::convert::Infallible;
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use bytes::Bytes;
use http_body_util::Full;
use hyper::body::Incoming;
use hyper::header::{HeaderValue, ALLOW, CONTENT_TYPE};
use hyper::service::service_fn;
use hyper::{Method, Request, Response, StatusCode};
use hyper_util::rt::TokioIo;
use prometheus::Registry;
use skymesh_runtime::WarnLimiter;
use tokio::net::TcpListener;
use tokio_util::sync::CancellationToken;
use tokio_util::task::TaskTracker;

use crate::console::{self, Console};
use crate::state::Mesh;
use crate::{health, metrics};

/// What the handlers read.
#[derive(Debug, Clone)]
pub struct App {
    pub mesh: Arc<Mesh>,
    pub registry: Registry,
    pub console: Arc<Console>,
    /// Budget of the 4xx warnings, per (peer address, status).
    pub refusals: Arc<Mutex<WarnLimiter<(std::net::IpAddr, u16)>>>,
}

fn reply(
    status: StatusCode,
    content_type: &'static str,
    body: impl Into<Bytes>,
) -> Response<Full<Bytes>> {
    let mut r = Response::new(Full::new(body.into()));
    *r.status_mut() = status;
    r.headers_mut()
        .insert(CONTENT_TYPE, HeaderValue::from_static(content_type));
    r
}

const TEXT: &str = "text/plain; charset=utf-8";

impl App {
    pub fn new(mesh: Arc<Mesh>, registry: Registry, console: Arc<Console>) -> Self {
        App {
            mesh,
            registry,
            console,
            refusals: Arc::new(Mutex::new(WarnLimiter::default())),
        }
    }

    /// Answers one request from `peer` (the console's actions may wait for an
    /// arbiter's answer), logging a refusal.
    pub async fn respond<B>(&self, req: &Request<B>, peer: SocketAddr) -> Response<Full<Bytes>> {
        let r = if console::is_console_path(req.uri().path()) {
            self.console.handle(req, peer).await
        } else {
            self.handle(req)
        };
        if r.status().is_client_error() {
            self.log_refusal(req, peer, r.status());
        }
        r
    }

    fn log_refusal<B>(&self, req: &Request<B>, peer: SocketAddr, status: StatusCode) {
        let path: String = req.uri().path().chars().take(120).collect();
        let allowed = self
            .refusals
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .allow((peer.ip(), status.as_u16()), Instant::now());
        match allowed {
            Some(hidden) => {
                tracing::warn!(%peer, method = %req.method(), path, status = status.as_u16(), hidden, "http request refused")
            }
            None => {
                tracing::debug!(%peer, method = %req.method(), path, status = status.as_u16(), "http request refused")
            }
        }
    }

    fn log_malformed(&self, peer: SocketAddr, e: &hyper::Error) {
        let allowed = self
            .refusals
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .allow((peer.ip(), 400), Instant::now());
        match allowed {
            Some(hidden) => tracing::warn!(%peer, error = %e, hidden, "malformed http request"),
            None => tracing::debug!(%peer, error = %e, "malformed http request"),
        }
    }

    /// Answers one request for the non-console paths.
    pub fn handle<B>(&self, req: &Request<B>) -> Response<Full<Bytes>> {
        let path = req.uri().path();
        if !matches!(path, "/metrics" | "/status" | "/healthz") {
            return reply(
                StatusCode::NOT_FOUND,
                TEXT,
                "not found: try / (the console), /metrics, /status or /healthz\n",
            );
        }
        if req.method() != Method::GET && req.method() != Method::HEAD {
            let mut r = reply(StatusCode::METHOD_NOT_ALLOWED, TEXT, "only GET\n");
            r.headers_mut()
                .insert(ALLOW, HeaderValue::from_static("GET, HEAD"));
            return r;
        }
        if path == "/metrics" {
            match metrics::render(&self.registry) {
                Ok(text) => reply(
                    StatusCode::OK,
                    "text/plain; version=0.0.4; charset=utf-8",
                    text,
                ),
                Err(e) => {
                    tracing::error!(error = %e, "encoding metrics failed");
                    reply(
                        StatusCode::INTERNAL_SERVER_ERROR,
                        TEXT,
                        format!("encoding metrics failed: {e}\n"),
                    )
                }
            }
        } else if path == "/healthz" {
            let report = health::report(&self.mesh.status());
            let status = StatusCode::from_u16(report.health.http_status())
                .unwrap_or(StatusCode::SERVICE_UNAVAILABLE);
            match serde_json::to_vec(&report) {
                Ok(mut body) => {
                    body.push(b'\n');
                    reply(status, "application/json", body)
                }
                Err(e) => reply(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    TEXT,
                    format!("encoding health failed: {e}\n"),
                ),
            }
        } else {
            match serde_json::to_vec(&self.mesh.status()) {
                Ok(body) => reply(StatusCode::OK, "application/json", body),
                Err(e) => reply(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    TEXT,
                    format!("encoding status failed: {e}\n"),
                ),
            }
        }
    }
}

/// Serves `app` on `listener` until `stop` is cancelled. Connection tasks run on
/// `tracker`, so the caller can wait for in-flight requests.
pub async fn serve(listener: TcpListener, app: App, stop: CancellationToken, tracker: TaskTracker) {
    loop {
        let accepted = tokio::select! {
            _ = stop.cancelled() => return,
            r = listener.accept() => r,
        };
        let (stream, peer) = match accepted {
            Ok(v) => v,
            Err(e) => {
                // Out of file descriptors and the like: back off instead of spinning.
                tracing::warn!(error = %e, "accept failed");
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                continue;
            }
        };
        let app = app.clone();
        let log_app = app.clone();
        let stop = stop.clone();
        tracker.spawn(async move {
            let svc = service_fn(move |req: Request<Incoming>| {
                let app = app.clone();
                async move { Ok::<_, Infallible>(app.respond(&req, peer).await) }
            });
            let conn = hyper::server::conn::http1::Builder::new()
                .serve_connection(TokioIo::new(stream), svc);
            let mut conn = std::pin::pin!(conn);
            tokio::select! {
                r = conn.as_mut() => {
                    match r {
                        // A request hyper could not parse (answered 400 or 431 by hyper).
                        Err(e) if e.is_parse() || e.is_parse_too_large() => {
                            log_app.log_malformed(peer, &e)
                        }
                        Err(e) => tracing::debug!(%peer, error = %e, "http connection ended with an error"),
                        Ok(()) => {}
                    }
                }
                _ = stop.cancelled() => {
                    conn.as_mut().graceful_shutdown();
                    let _ = tokio::time::timeout(std::time::Duration::from_secs(1), conn).await;
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn app(mesh: Arc<Mesh>) -> App {
        let vehicles = Arc::new(crate::vehicles::VehicleGauges::new(&[1]));
        let console = Console::new(mesh.clone(), vehicles, None, Default::default());
        App::new(
            mesh.clone(),
            metrics::registry(mesh).unwrap(),
            Arc::new(console),
        )
    }

    #[test]
    fn routes() {
        let mesh = Arc::new(Mesh::new(&[("a".into(), false)], false));
        let app = app(mesh);
        let get = |p: &str| app.handle(&Request::get(p).body(()).unwrap());
        assert_eq!(get("/metrics").status(), StatusCode::OK);
        let status = get("/status");
        assert_eq!(status.status(), StatusCode::OK);
        assert_eq!(status.headers()[CONTENT_TYPE], "application/json");
        assert_eq!(get("/metricsx").status(), StatusCode::NOT_FOUND);
        assert_eq!(get("/favicon.ico").status(), StatusCode::NOT_FOUND);
        // The console's paths go to the console.
        assert!(console::is_console_path("/"));
        assert!(console::is_console_path("/api/mesh"));
        assert!(!console::is_console_path("/status"));
        let post = app.handle(&Request::post("/status").body(()).unwrap());
        assert_eq!(post.status(), StatusCode::METHOD_NOT_ALLOWED);
    }

    fn body_json(r: Response<Full<Bytes>>) -> serde_json::Value {
        use http_body_util::BodyExt as _;
        let bytes = block_on(r.into_body().collect()).unwrap().to_bytes();
        serde_json::from_slice(&bytes).unwrap()
    }

    fn block_on<F: std::future::Future>(f: F) -> F::Output {
        tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap()
            .block_on(f)
    }

    #[test]
    fn healthz_is_200_only_when_every_service_runs() {
        use crate::state::Phase;
        let mesh = Arc::new(Mesh::new(&[("a".into(), true), ("b".into(), false)], false));
        let app = app(mesh.clone());
        let get = || app.handle(&Request::get("/healthz").body(()).unwrap());

        // Both still starting.
        let r = get();
        assert_eq!(r.status(), StatusCode::SERVICE_UNAVAILABLE);
        assert_eq!(r.headers()[CONTENT_TYPE], "application/json");
        assert_eq!(body_json(r)["health"], "degraded");

        mesh.set_phase(0, Phase::Running);
        mesh.set_phase(1, Phase::Running);
        let r = get();
        assert_eq!(r.status(), StatusCode::OK);
        let v = body_json(r);
        assert_eq!(v["health"], "ok");
        assert_eq!(v["exit_code"], 0);
        assert_eq!(v["running"], 2);

        mesh.set_phase(1, Phase::Backoff);
        let r = get();
        assert_eq!(r.status(), StatusCode::SERVICE_UNAVAILABLE);
        let v = body_json(r);
        assert_eq!(
            (v["health"].as_str(), v["exit_code"].as_u64()),
            (Some("degraded"), Some(1))
        );
        assert_eq!(v["not_running"][0]["name"], "b");

        mesh.set_phase(0, Phase::Failed);
        let r = get();
        assert_eq!(r.status(), StatusCode::SERVICE_UNAVAILABLE);
        let v = body_json(r);
        assert_eq!(
            (v["health"].as_str(), v["exit_code"].as_u64()),
            (Some("critical"), Some(2))
        );
    }
}
