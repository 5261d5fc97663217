//! The TLS listener: rumqttc clients over TLS (rustls with `ring`, as the DJI
//! gateway connects) against the in-process broker, with the certificates in
//! `tests/fixtures/` (see its README). rumqttd cannot be stopped inside a process:
//! every test uses its own ports.

mod common;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use common::*;
use rumqttc::{
    AsyncClient, ConnectionError, Event, EventLoop, Packet, QoS, TlsConfiguration, Transport,
};
use skymesh_test_support::{config_file, text, ServiceCli};
use tokio::io::AsyncWriteExt as _;
use tokio_rustls::rustls::pki_types::{pem::PemObject, PrivateKeyDer};
use tokio_rustls::rustls::{self, pki_types::CertificateDer, ClientConfig, RootCertStore};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn certs(name: &str) -> Vec<CertificateDer<'static>> {
    let pem = std::fs::read(fixture(name)).expect("fixture");
    CertificateDer::pem_slice_iter(&pem)
        .collect::<Result<Vec<_>, _>>()
        .expect("fixture PEM")
}

/// A client config trusting `ca` (as dji-gateway's `tls::client_config`), with the
/// test client certificate when `with_cert`.
fn client_tls(ca: &str, with_cert: bool) -> Transport {
    let mut roots = RootCertStore::empty();
    for c in certs(ca) {
        roots.add(c).expect("CA");
    }
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let builder = ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .expect("versions")
        .with_root_certificates(roots);
    let config = if with_cert {
        let key = std::fs::read(fixture("client.key")).expect("client key");
        let key = PrivateKeyDer::from_pem_slice(&key).expect("a PEM key");
        builder
            .with_client_auth_cert(certs("client.pem"), key)
            .expect("client cert")
    } else {
        builder.with_no_client_auth()
    };
    Transport::Tls(TlsConfiguration::Rustls(Arc::new(config)))
}

/// The `[tls]` table for the fixtures on `addr`, plus `extra` lines.
fn tls_table(addr: SocketAddr, extra: &str) -> String {
    format!(
        "[tls]\nlisten = \"{addr}\"\ncert_file = \"{}\"\nkey_file = \"{}\"\n{extra}\n",
        fixture("server.pem").display(),
        fixture("server.key").display()
    )
}

/// The in-process broker and its TLS listener.
struct Broker {
    /// The TLS listener.
    tls: SocketAddr,
    run: Running,
}

impl std::ops::Deref for Broker {
    type Target = Running;
    fn deref(&self) -> &Running {
        &self.run
    }
}

/// The broker with `top` (top-level TOML: users, timeouts) and a TLS listener
/// (`tls_extra` appended to its table).
async fn start(top: &str, tls_extra: &str) -> Broker {
    let (run, [_, tls]) = Running::start_on_free_ports(|[plain, tls]| {
        config_toml(plain, &format!("{top}\n{}", tls_table(tls, tls_extra)))
    })
    .await;
    Broker { tls, run }
}

impl Broker {
    async fn stop(self) {
        self.run.stop().await;
    }

    fn refused(&self, reason: &str) -> f64 {
        self.stats
            .value(
                "skymesh_mqtt_tls_refused_total",
                &format!("reason={reason}"),
            )
            .unwrap_or(0.0)
    }
}

fn tls_client(
    addr: SocketAddr,
    id: &str,
    login: Option<(&str, &str)>,
    transport: Transport,
) -> (AsyncClient, EventLoop) {
    let mut o = options(addr, id, login);
    o.set_transport(transport);
    AsyncClient::new(o, 16)
}

/// Polls until CONNACK (retrying while the listener is not accepting yet).
async fn connected(
    addr: SocketAddr,
    id: &str,
    login: Option<(&str, &str)>,
    transport: Transport,
) -> (AsyncClient, EventLoop) {
    let (client, mut ev) = tls_client(addr, id, login, transport);
    tokio::time::timeout(PATIENCE, async {
        loop {
            match ev.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => return,
                Ok(_) => {}
                Err(e) => {
                    eprintln!("{id}: {e}, retrying");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            }
        }
    })
    .await
    .unwrap_or_else(|_| panic!("{id}: no CONNACK within {PATIENCE:?}"));
    (client, ev)
}

/// The first poll of a new connection must fail: returns the error.
async fn refused(
    addr: SocketAddr,
    id: &str,
    login: Option<(&str, &str)>,
    transport: Transport,
) -> ConnectionError {
    let (_c, mut ev) = tls_client(addr, id, login, transport);
    match tokio::time::timeout(PATIENCE, ev.poll()).await {
        Ok(Err(e)) => e,
        Ok(Ok(event)) => panic!("{id}: the connection must fail, got {event:?}"),
        Err(_) => panic!("{id}: no answer within {PATIENCE:?}"),
    }
}

#[tokio::test]
async fn a_client_trusting_the_ca_subscribes_and_receives_and_logins_still_apply() {
    let broker = start(
        "[[user]]\nname = \"cloud\"\npassword = \"s3cret\"\n\
         publish = [\"skymesh/tls/#\"]\nsubscribe = [\"skymesh/tls/#\"]",
        "",
    )
    .await;
    let login = Some(("cloud", "s3cret"));
    let (sub, mut sub_ev) = connected(broker.tls, "sub", login, client_tls("ca.pem", false)).await;
    sub.subscribe("skymesh/tls/#", QoS::AtLeastOnce)
        .await
        .unwrap();
    until_incoming(&mut sub_ev, "SUBACK", |p| matches!(p, Packet::SubAck(_))).await;
    let (publisher, ev) = connected(broker.tls, "pub", login, client_tls("ca.pem", false)).await;
    let _driver = drive(ev);
    publisher
        .publish("skymesh/tls/x", QoS::AtLeastOnce, false, "over tls")
        .await
        .unwrap();
    let p = next_publish(&mut sub_ev, "the publish over TLS").await;
    assert_eq!(
        (p.topic.as_str(), &p.payload[..]),
        ("skymesh/tls/x", &b"over tls"[..])
    );
    broker
        .until_metric("skymesh_mqtt_tls_connections_total", "", 2.0)
        .await;

    // The broker's logins apply behind the terminator (the handshake succeeds, the
    // CONNECT is refused by the gate).
    let e = refused(
        broker.tls,
        "wrong-password",
        Some(("cloud", "nope")),
        client_tls("ca.pem", false),
    )
    .await;
    assert!(
        !matches!(e, ConnectionError::Tls(_)),
        "a login refusal, not TLS: {e}"
    );
    broker.stop().await;
}

#[tokio::test]
async fn plain_mqtt_on_the_tls_port_fails_and_is_counted() {
    let broker = start("", "").await;
    // The TLS port works (the broker behind it is up)...
    let (_ok, _ok_ev) = connected(broker.tls, "tls", None, client_tls("ca.pem", false)).await;
    // ...a plain MQTT client there does not.
    let (_c, mut ev) = AsyncClient::new(options(broker.tls, "plain", None), 4);
    match tokio::time::timeout(PATIENCE, ev.poll()).await {
        Ok(Err(_)) => {}
        Ok(Ok(event)) => panic!("plain MQTT on the TLS port must fail, got {event:?}"),
        Err(_) => panic!("no answer within {PATIENCE:?}"),
    }
    broker
        .until_metric("skymesh_mqtt_tls_refused_total", "reason=not_tls", 1.0)
        .await;
    broker.stop().await;
}

#[tokio::test]
async fn a_client_trusting_another_ca_fails() {
    let broker = start("", "").await;
    let (_ok, _ok_ev) = connected(broker.tls, "good", None, client_tls("ca.pem", false)).await;
    let e = refused(
        broker.tls,
        "other-ca",
        None,
        client_tls("other-ca.pem", false),
    )
    .await;
    assert!(matches!(e, ConnectionError::Tls(_)), "{e}");
    assert!(e.to_string().contains("certificate"), "{e}");
    // rustls tells the server why (an alert) before it closes.
    broker
        .until_metric("skymesh_mqtt_tls_refused_total", "reason=client_alert", 1.0)
        .await;
    assert_eq!(
        broker
            .stats
            .value("skymesh_mqtt_tls_connections_total", "")
            .unwrap_or(0.0),
        1.0,
        "only the good client was forwarded"
    );
    broker.stop().await;
}

#[tokio::test]
async fn client_certificates_are_required_with_client_ca_file() {
    let ca = fixture("ca.pem");
    let broker = start("", &format!("client_ca_file = \"{}\"", ca.display())).await;
    let (with_cert, ev) =
        connected(broker.tls, "with-cert", None, client_tls("ca.pem", true)).await;
    let _driver = drive(ev);
    with_cert
        .publish("skymesh/tls/cert", QoS::AtMostOnce, false, "ok")
        .await
        .unwrap();
    // Without a certificate: rustls on TLS 1.3 reports the refusal after the
    // client's handshake is done, so the failure shows at CONNECT or right after.
    let (_c, mut ev) = tls_client(broker.tls, "no-cert", None, client_tls("ca.pem", false));
    let outcome = tokio::time::timeout(PATIENCE, async {
        loop {
            match ev.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => return Ok(()),
                Ok(_) => {}
                Err(e) => return Err(e),
            }
        }
    })
    .await
    .expect("an answer within patience");
    assert!(
        outcome.is_err(),
        "a client without a certificate was served"
    );
    broker
        .until_metric(
            "skymesh_mqtt_tls_refused_total",
            "reason=client_certificate",
            1.0,
        )
        .await;
    assert_eq!(broker.refused("handshake"), 0.0);
    broker.stop().await;
}

#[tokio::test]
async fn a_silent_connection_does_not_hold_up_others_and_times_out() {
    let broker = start("connection_timeout_ms = 300", "").await;
    // A TCP connection that never starts a handshake...
    let mut silent = tokio::net::TcpStream::connect(broker.tls).await.unwrap();
    // ...does not stop the next client from connecting.
    let (_ok, _ok_ev) = connected(broker.tls, "next", None, client_tls("ca.pem", false)).await;
    broker
        .until_metric(
            "skymesh_mqtt_tls_refused_total",
            "reason=handshake_timeout",
            1.0,
        )
        .await;
    // The terminator closed it: a read sees the end (or a reset), not a hang.
    let mut buf = [0u8; 16];
    let n = tokio::time::timeout(
        PATIENCE,
        tokio::io::AsyncReadExt::read(&mut silent, &mut buf),
    )
    .await
    .expect("the silent connection is closed");
    assert!(matches!(n, Ok(0) | Err(_)), "{n:?}");
    let _ = silent.shutdown().await;
    broker.stop().await;
}

fn broker_cli() -> ServiceCli {
    ServiceCli::new(env!("CARGO_BIN_EXE_skymesh-mqtt-broker"), "mqtttls")
}

#[tokio::test]
async fn check_config_reads_and_matches_the_tls_files() {
    let f = |n: &str| fixture(n).display().to_string();
    let ok = format!(
        "[tls]\ncert_file = \"{}\"\nkey_file = \"{}\"\nclient_ca_file = \"{}\"\n",
        f("server.pem"),
        f("server.key"),
        f("ca.pem")
    );
    let out = broker_cli().run_toml(&ok, &["--check-config"]).await;
    assert_eq!(out.status.code(), Some(0), "{}", text(&out));

    let tls = |cert: &str, key: &str, extra: &str| {
        format!("[tls]\ncert_file = \"{cert}\"\nkey_file = \"{key}\"\n{extra}\n")
    };
    let (cert, key) = (f("server.pem"), f("server.key"));
    let cases = [
        (format!("[tls]\nkey_file = \"{key}\"\n"), "tls.cert_file"),
        (format!("[tls]\ncert_file = \"{cert}\"\n"), "tls.key_file"),
        (tls("/nonexistent/server.pem", &key, ""), "tls.cert_file"),
        (tls(&cert, "/nonexistent/server.key", ""), "tls.key_file"),
        (tls("/dev/zero", &key, ""), "tls.cert_file"),
        // A key file given as the certificate and the reverse.
        (tls(&key, &key, ""), "tls.cert_file"),
        (tls(&cert, &cert, ""), "tls.key_file"),
        // The client's key with the server's certificate.
        (tls(&cert, &f("client.key"), ""), "tls.key_file"),
        (
            tls(&cert, &key, &format!("client_ca_file = \"{key}\"")),
            "tls.client_ca_file",
        ),
        (
            tls(&cert, &key, "listen = \"127.0.0.1:1883\""),
            "tls.listen",
        ),
        (tls(&cert, &key, "listen = \"127.0.0.1:0\""), "tls.listen"),
        (
            format!(
                "listen = \"0.0.0.0:1883\"\n{}",
                tls(
                    &cert,
                    &key,
                    &format!("client_ca_file = \"{}\"", f("ca.pem"))
                )
            ),
            "tls.client_ca_file",
        ),
        // Reachable from elsewhere with neither logins nor client certificates.
        (tls(&cert, &key, "listen = \"0.0.0.0:8883\""), "tls.listen"),
    ];
    for (toml, field) in &cases {
        broker_cli().expect_config_error(toml, field).await;
    }
    // A certificate whose PEM body is not a certificate.
    let garbage = config_file("-----BEGIN CERTIFICATE-----\nAAAA\n-----END CERTIFICATE-----\n");
    broker_cli()
        .expect_config_error(
            &tls(&garbage.path().display().to_string(), &key, ""),
            "tls.cert_file",
        )
        .await;
}

/// Broken PEM (a cut-off file, a mangled header line, a body that is not base64)
/// is a configuration error (exit 64) that names the key and says what is wrong in
/// words.
#[tokio::test]
async fn broken_pem_files_are_refused_with_the_reason() {
    let fixture_text = |n: &str| std::fs::read_to_string(fixture(n)).expect("fixture");
    let (cert_pem, key_pem) = (fixture_text("server.pem"), fixture_text("server.key"));
    let cut = |pem: &str| pem[..pem.find("-----END").expect("END line")].to_owned();
    let (cert, key) = (
        fixture("server.pem").display().to_string(),
        fixture("server.key").display().to_string(),
    );
    let tls =
        |cert: &str, key: &str| format!("[tls]\ncert_file = \"{cert}\"\nkey_file = \"{key}\"\n");
    let cases = [
        // (file text, is it the key file, words the error must contain)
        (
            cut(&cert_pem),
            false,
            "`-----END CERTIFICATE-----` line is missing",
        ),
        (cut(&key_pem), true, "-----END"),
        (
            cert_pem.replacen(
                "-----BEGIN CERTIFICATE-----",
                "-----BEGIN CERTIFICATE---",
                1,
            ),
            false,
            "malformed line `-----BEGIN CERTIFICATE---`",
        ),
        (
            "-----BEGIN PRIVATE KEY-----\n!!!!\n-----END PRIVATE KEY-----\n".to_owned(),
            true,
            "not valid base64",
        ),
        // A key file holding only a certificate.
        (cert_pem.clone(), true, "no private key in the file"),
    ];
    for (pem, is_key, words) in cases {
        let file = config_file(&pem);
        let path = file.path().display().to_string();
        let (toml, field) = if is_key {
            (tls(&cert, &path), "tls.key_file")
        } else {
            (tls(&path, &key), "tls.cert_file")
        };
        let out = broker_cli().run_toml(&toml, &["--check-config"]).await;
        assert_eq!(out.status.code(), Some(64), "{toml:?}\n{}", text(&out));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains(field) && stderr.contains(words),
            "{pem:?} should name {field} and say {words:?}\n{}",
            text(&out)
        );
    }
}
