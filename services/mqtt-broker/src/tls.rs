//! The optional TLS listener: a TLS terminator in this service that hands each
//! decrypted connection to the gate ([`crate::gate`]), which forwards it to rumqttd.
//!
//! Why not rumqttd's own `use-rustls` feature: rumqttd 0.20 performs the TLS
//! handshake inside its accept loop without a timeout (one client that opens a TCP
//! connection and sends nothing stops every later client from connecting), makes
//! client certificates a compile-time feature (`verify-client-cert`, which also
//! reads a tenant id out of them), reports handshake failures only in its log, and
//! pulls a second rustls (0.22) plus x509-parser and syn 1 into the tree. Here the
//! handshake has `connection_timeout_ms`, client certificates are a config key,
//! connections are bounded by `max_connections`, every refusal is counted in
//! `skymesh_mqtt_tls_refused_total{reason}`, and the rustls 0.23 / `ring` stack is
//! the one the DJI gateway already uses.

use std::net::{IpAddr, SocketAddr};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use skymesh_runtime::config::{read_regular_file, FileReadError};
use skymesh_runtime::{CancellationToken, Counter, CounterFamily, Gauge, Stats, WarnLimiter};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Semaphore;
use tokio_rustls::rustls::pki_types::pem::{self, PemObject};
use tokio_rustls::rustls::{
    self, crypto::CryptoProvider, pki_types::CertificateDer, pki_types::PrivateKeyDer,
    server::WebPkiClientVerifier, RootCertStore, ServerConfig,
};
use tokio_rustls::TlsAcceptor;

/// The validated `[tls]` table.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsSettings {
    /// Where TLS clients connect.
    pub listen: SocketAddr,
    /// PEM certificate chain, the server's certificate first.
    pub cert_file: PathBuf,
    /// PEM private key (PKCS#8, PKCS#1 or SEC1) of the first certificate.
    pub key_file: PathBuf,
    /// PEM CA bundle: when set, clients must present a certificate it signed.
    pub client_ca_file: Option<PathBuf>,
}

/// Why the TLS files cannot be used. `key()` names the config key at fault.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// Missing, unreadable, not a regular file, or larger than [`MAX_PEM_BYTES`].
    #[error("{source}")]
    File {
        key: &'static str,
        source: FileReadError,
    },
    #[error("{path}: not valid PEM: {reason}")]
    Pem {
        key: &'static str,
        path: PathBuf,
        reason: String,
    },
    #[error("{path}: no certificate in the file (expected PEM `BEGIN CERTIFICATE` blocks)")]
    NoCertificate { key: &'static str, path: PathBuf },
    #[error("{path}: no private key in the file (expected PEM `BEGIN PRIVATE KEY`, `BEGIN RSA PRIVATE KEY` or `BEGIN EC PRIVATE KEY`)")]
    NoKey { key: &'static str, path: PathBuf },
    #[error("{path}: no usable CA certificate ({rejected} rejected)")]
    NoUsableCa { path: PathBuf, rejected: usize },
    #[error("{key}: {source}")]
    Rustls {
        key: &'static str,
        source: rustls::Error,
    },
}

impl TlsError {
    /// The config key the error is about (`tls.cert_file`, ...).
    pub fn key(&self) -> &'static str {
        match self {
            TlsError::File { key, .. }
            | TlsError::Pem { key, .. }
            | TlsError::NoCertificate { key, .. }
            | TlsError::NoKey { key, .. }
            | TlsError::Rustls { key, .. } => key,
            TlsError::NoUsableCa { .. } => "tls.client_ca_file",
        }
    }
}

/// The largest PEM file read (a CA bundle is about 200 KiB).
pub const MAX_PEM_BYTES: u64 = 1 << 20;

/// Reads a regular file of at most [`MAX_PEM_BYTES`]; a device, FIFO or directory is
/// refused before it is opened (it could block or never end).
fn read_pem(key: &'static str, path: &Path) -> Result<Vec<u8>, TlsError> {
    read_regular_file(path, MAX_PEM_BYTES).map_err(|source| TlsError::File { key, source })
}

/// What is wrong with a PEM file, in words: `pem::Error`'s own text prints the
/// section label and the bad line as lists of byte values.
fn pem_reason(e: &pem::Error) -> String {
    match e {
        pem::Error::MissingSectionEnd { end_marker } => format!(
            "the `-----END {}-----` line is missing",
            String::from_utf8_lossy(end_marker)
        ),
        pem::Error::IllegalSectionStart { line } => format!(
            "malformed line `{}` (expected `-----BEGIN <LABEL>-----`)",
            String::from_utf8_lossy(line).trim_end()
        ),
        pem::Error::Base64Decode(_) => "a section's body is not valid base64".to_owned(),
        other => other.to_string(),
    }
}

fn certificates(key: &'static str, path: &Path) -> Result<Vec<CertificateDer<'static>>, TlsError> {
    let text = read_pem(key, path)?;
    let certs = CertificateDer::pem_slice_iter(&text)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| TlsError::Pem {
            key,
            path: path.to_path_buf(),
            reason: pem_reason(&e),
        })?;
    if certs.is_empty() {
        return Err(TlsError::NoCertificate {
            key,
            path: path.to_path_buf(),
        });
    }
    Ok(certs)
}

fn private_key(path: &Path) -> Result<PrivateKeyDer<'static>, TlsError> {
    const KEY: &str = "tls.key_file";
    let text = read_pem(KEY, path)?;
    PrivateKeyDer::from_pem_slice(&text).map_err(|e| match e {
        pem::Error::NoItemsFound => TlsError::NoKey {
            key: KEY,
            path: path.to_path_buf(),
        },
        e => TlsError::Pem {
            key: KEY,
            path: path.to_path_buf(),
            reason: pem_reason(&e),
        },
    })
}

/// The rustls server configuration of `s` (ring provider, TLS 1.2 and 1.3): reads
/// and parses every file and checks that the key belongs to the certificate. Used
/// by the config check and at start.
pub fn server_config(s: &TlsSettings) -> Result<Arc<ServerConfig>, TlsError> {
    let chain = certificates("tls.cert_file", &s.cert_file)?;
    let key = private_key(&s.key_file)?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let builder = ServerConfig::builder_with_provider(provider.clone())
        .with_safe_default_protocol_versions()
        .map_err(|source| TlsError::Rustls { key: "tls", source })?;
    let builder = match &s.client_ca_file {
        None => builder.with_no_client_auth(),
        Some(path) => {
            let verifier = client_verifier(path, provider)?;
            builder.with_client_cert_verifier(verifier)
        }
    };
    let config = builder.with_single_cert(chain, key).map_err(|source| {
        // A key that does not match the certificate, or a key rustls cannot use,
        // is the key's fault; anything else the certificate's.
        let key = match source {
            rustls::Error::InconsistentKeys(_) | rustls::Error::General(_) => "tls.key_file",
            _ => "tls.cert_file",
        };
        TlsError::Rustls { key, source }
    })?;
    Ok(Arc::new(config))
}

fn client_verifier(
    path: &Path,
    provider: Arc<CryptoProvider>,
) -> Result<Arc<dyn rustls::server::danger::ClientCertVerifier>, TlsError> {
    let certs = certificates("tls.client_ca_file", path)?;
    let mut roots = RootCertStore::empty();
    let (_, rejected) = roots.add_parsable_certificates(certs);
    if roots.is_empty() {
        return Err(TlsError::NoUsableCa {
            path: path.to_path_buf(),
            rejected,
        });
    }
    WebPkiClientVerifier::builder_with_provider(Arc::new(roots), provider)
        .build()
        .map_err(|e| TlsError::Rustls {
            key: "tls.client_ca_file",
            source: rustls::Error::General(e.to_string()),
        })
}

/// Why a TLS connection was refused (label `reason`, a closed set).
pub mod reason {
    /// `max_connections` TLS connections are open (or in their handshake).
    pub const TOO_MANY: &str = "too_many_connections";
    /// No finished handshake within `connection_timeout_ms`.
    pub const TIMEOUT: &str = "handshake_timeout";
    /// The client did not speak TLS (e.g. plain MQTT on the TLS port).
    pub const NOT_TLS: &str = "not_tls";
    /// No client certificate, or one the `client_ca_file` did not sign.
    pub const CLIENT_CERTIFICATE: &str = "client_certificate";
    /// The client aborted with an alert (typically: it does not trust our certificate).
    pub const CLIENT_ALERT: &str = "client_alert";
    /// Any other handshake failure (no common version or cipher, connection closed).
    pub const HANDSHAKE: &str = "handshake";
    pub const ALL: [&str; 6] = [
        TOO_MANY,
        TIMEOUT,
        NOT_TLS,
        CLIENT_CERTIFICATE,
        CLIENT_ALERT,
        HANDSHAKE,
    ];
}

/// The reason label of a failed handshake.
fn classify(e: &std::io::Error) -> &'static str {
    let Some(tls) = e.get_ref().and_then(|i| i.downcast_ref::<rustls::Error>()) else {
        return reason::HANDSHAKE;
    };
    match tls {
        rustls::Error::InvalidMessage(_) => reason::NOT_TLS,
        rustls::Error::NoCertificatesPresented | rustls::Error::InvalidCertificate(_) => {
            reason::CLIENT_CERTIFICATE
        }
        rustls::Error::AlertReceived(_) => reason::CLIENT_ALERT,
        _ => reason::HANDSHAKE,
    }
}

/// The TLS listener's series.
#[derive(Debug, Clone)]
pub struct TlsMetrics {
    /// `skymesh_mqtt_tls_connections_total`: handshakes completed and forwarded.
    pub accepted: Counter,
    /// `skymesh_mqtt_tls_connections`: TLS connections open now (handshakes included).
    pub open: Gauge,
    /// `skymesh_mqtt_tls_refused_total{reason}` (see [`reason`]).
    refused: CounterFamily,
}

impl TlsMetrics {
    pub fn new(stats: &Stats) -> Self {
        TlsMetrics {
            accepted: stats.counter("skymesh_mqtt_tls_connections_total", &[]),
            open: stats.gauge("skymesh_mqtt_tls_connections", &[]),
            refused: CounterFamily::new(stats, "skymesh_mqtt_tls_refused_total", ("reason", None)),
        }
    }
}

/// Counts and logs (at most one warning per client address and reason every
/// [`skymesh_runtime::WARN_EVERY`]) refused TLS connections.
#[derive(Debug, Clone)]
struct Refusals {
    metrics: TlsMetrics,
    limiter: Arc<Mutex<WarnLimiter<(IpAddr, &'static str)>>>,
}

impl Refusals {
    fn record(&self, peer: SocketAddr, reason: &'static str, detail: &dyn std::fmt::Display) {
        self.metrics.refused.inc(reason);
        let allowed = self
            .limiter
            .lock()
            .map(|mut l| l.allow((peer.ip(), reason), Instant::now()))
            .unwrap_or(Some(0));
        match allowed {
            Some(hidden) => tracing::warn!(
                %peer,
                reason,
                detail = %detail,
                similar_since_last_warning = hidden,
                "TLS connection refused"
            ),
            None => tracing::debug!(%peer, reason, detail = %detail, "TLS connection refused"),
        }
    }
}

/// The running terminator's parameters.
#[derive(Clone)]
pub struct Terminator {
    pub acceptor: TlsAcceptor,
    /// Where each connection goes once its handshake is done.
    pub gate: Arc<crate::gate::Gate>,
    pub handshake_timeout: Duration,
    pub max_connections: usize,
}

impl std::fmt::Debug for Terminator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Terminator")
            .field("gate", &self.gate)
            .field("handshake_timeout", &self.handshake_timeout)
            .field("max_connections", &self.max_connections)
            .finish_non_exhaustive()
    }
}

/// Accepts TLS connections on `listener` until `shutdown`, each forwarded to
/// the gate once its handshake is done. Open connections outlive the shutdown
/// (as rumqttd's do: they end with the process).
pub async fn serve(
    listener: TcpListener,
    t: Terminator,
    metrics: TlsMetrics,
    shutdown: CancellationToken,
) {
    let slots = Arc::new(Semaphore::new(t.max_connections));
    let refusals = Refusals {
        metrics: metrics.clone(),
        limiter: Arc::default(),
    };
    loop {
        let (stream, peer) = tokio::select! {
            _ = shutdown.cancelled() => return,
            r = listener.accept() => match r {
                Ok(x) => x,
                Err(e) => {
                    // Out of descriptors and the like: not the client's doing, not
                    // fatal; a pause keeps a persistent error from spinning.
                    tracing::warn!(error = %e, "TLS listener: accept failed");
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    continue;
                }
            },
        };
        let Ok(slot) = slots.clone().try_acquire_owned() else {
            refusals.record(
                peer,
                reason::TOO_MANY,
                &format_args!("{} TLS connections are open", t.max_connections),
            );
            drop(stream);
            continue;
        };
        let open = |slots: &Semaphore| (t.max_connections - slots.available_permits()) as f64;
        metrics.open.set(open(&slots));
        let t = t.clone();
        let refusals = refusals.clone();
        let metrics = metrics.clone();
        let slots = slots.clone();
        tokio::spawn(async move {
            connection(stream, peer, &t, &refusals, &metrics).await;
            drop(slot);
            metrics
                .open
                .set((t.max_connections - slots.available_permits()) as f64);
        });
    }
}

/// One client: handshake (bounded in time), connect to rumqttd, copy both ways.
async fn connection(
    stream: TcpStream,
    peer: SocketAddr,
    t: &Terminator,
    refusals: &Refusals,
    metrics: &TlsMetrics,
) {
    let tls = match tokio::time::timeout(t.handshake_timeout, t.acceptor.accept(stream)).await {
        Err(_) => {
            refusals.record(
                peer,
                reason::TIMEOUT,
                &format_args!("no TLS handshake within {:?}", t.handshake_timeout),
            );
            return;
        }
        Ok(Err(e)) => {
            refusals.record(peer, classify(&e), &e);
            return;
        }
        Ok(Ok(s)) => s,
    };
    metrics.accepted.inc();
    tracing::debug!(%peer, "TLS connection handed to the gate");
    t.gate.client(tls, peer).await;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_reason_is_distinct() {
        let mut r = reason::ALL.to_vec();
        r.sort_unstable();
        r.dedup();
        assert_eq!(r.len(), reason::ALL.len());
    }

    #[test]
    fn plain_bytes_are_not_tls() {
        let e = std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            rustls::Error::InvalidMessage(rustls::InvalidMessage::InvalidContentType),
        );
        assert_eq!(classify(&e), reason::NOT_TLS);
        let eof = std::io::Error::from(std::io::ErrorKind::UnexpectedEof);
        assert_eq!(classify(&eof), reason::HANDSHAKE);
    }
}
