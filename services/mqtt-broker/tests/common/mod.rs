//! Helpers shared by the broker tests: free ports, configs, `rumqttc` clients.

#![allow(dead_code)]

use std::net::SocketAddr;
use std::time::Duration;

use rumqttc::{AsyncClient, ConnectionError, Event, EventLoop, MqttOptions, Packet, Publish};
use skymesh_mqtt_broker::{serve, BrokerError, RawConfig};
use skymesh_runtime::config::parse;
use skymesh_runtime::{CancellationToken, Stats};
use tokio::task::JoinHandle;

/// How long a test waits for something that should happen (never a timing claim).
pub const PATIENCE: Duration = Duration::from_secs(20);

/// A 127.0.0.1 port that was free a moment ago (bind port 0, read it, release it).
pub fn free_addr() -> SocketAddr {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("bind port 0");
    l.local_addr().expect("local addr")
}

/// A broker config listening on `addr` with `extra` TOML appended.
pub fn config_toml(addr: SocketAddr, extra: &str) -> String {
    format!("listen = \"{addr}\"\nmeters_interval_s = 1\n{extra}\n")
}

/// The broker served in-process ([`serve`]) until [`Running::stop`].
pub struct Running {
    pub stats: Stats,
    shutdown: CancellationToken,
    task: JoinHandle<Result<(), BrokerError>>,
}

impl Running {
    /// Serves the broker config `toml`; returns once the broker is ready.
    pub async fn start(toml: &str) -> Running {
        Running::try_start(toml)
            .await
            .unwrap_or_else(|e| panic!("the broker did not start: {e:#}"))
    }

    /// Serves a config made by `toml` for free ports (`N` of them, distinct), and
    /// picks new ports when one of them was taken between being picked and the
    /// broker binding it (another test, or the broker's own loopback listener): a
    /// free port is only free when it is picked. Returns the broker and its ports.
    pub async fn start_on_free_ports<const N: usize>(
        toml: impl Fn([SocketAddr; N]) -> String,
    ) -> (Running, [SocketAddr; N]) {
        let mut attempt = 0;
        loop {
            attempt += 1;
            let held: Vec<std::net::TcpListener> = (0..N)
                .map(|_| std::net::TcpListener::bind("127.0.0.1:0").expect("bind port 0"))
                .collect();
            let addrs: [SocketAddr; N] =
                std::array::from_fn(|i| held[i].local_addr().expect("local addr"));
            drop(held);
            match Running::try_start(&toml(addrs)).await {
                Ok(run) => return (run, addrs),
                Err(e @ (BrokerError::Listen { .. } | BrokerError::Stopped(_))) if attempt < 5 => {
                    eprintln!("the broker did not start on {addrs:?} ({e:#}): other ports");
                }
                Err(e) => panic!("the broker did not start: {e:#}"),
            }
        }
    }

    /// Serves the broker config `toml`; returns once the broker is ready, or the
    /// error it stopped with before that.
    pub async fn try_start(toml: &str) -> Result<Running, BrokerError> {
        let settings = parse::<RawConfig>(toml, "test").expect("test config is valid");
        let stats = Stats::new();
        let shutdown = CancellationToken::new();
        let (ready_tx, ready_rx) = tokio::sync::oneshot::channel();
        let task = tokio::spawn(serve(
            settings,
            stats.clone(),
            shutdown.clone(),
            move || {
                let _ = ready_tx.send(());
            },
        ));
        let ready = tokio::time::timeout(PATIENCE, ready_rx)
            .await
            .expect("ready within patience");
        if ready.is_err() {
            // `serve` returned without calling `ready`.
            return Err(task
                .await
                .expect("the broker task")
                .expect_err("serve returned Ok before it was ready"));
        }
        Ok(Running {
            stats,
            shutdown,
            task,
        })
    }

    /// Asks the broker to stop and checks that `serve` returned Ok.
    pub async fn stop(self) {
        self.shutdown.cancel();
        let r = tokio::time::timeout(PATIENCE, self.task)
            .await
            .expect("serve returns after the shutdown request")
            .expect("serve did not panic");
        assert!(r.is_ok(), "{r:?}");
    }

    /// Waits until `name{labels}` reaches at least `min`; returns its value.
    pub async fn until_metric(&self, name: &str, labels: &str, min: f64) -> f64 {
        tokio::time::timeout(PATIENCE, async {
            loop {
                match self.stats.value(name, labels) {
                    Some(v) if v >= min => return v,
                    _ => tokio::time::sleep(Duration::from_millis(20)).await,
                }
            }
        })
        .await
        .unwrap_or_else(|_| {
            panic!(
                "{name}{{{labels}}} is {:?}, expected at least {min}",
                self.stats.value(name, labels)
            )
        })
    }
}

pub fn options(addr: SocketAddr, id: &str, login: Option<(&str, &str)>) -> MqttOptions {
    let mut o = MqttOptions::new(id, addr.ip().to_string(), addr.port());
    o.set_keep_alive(Duration::from_secs(30));
    // Large enough to try sending packets the broker must refuse.
    o.set_max_packet_size(1 << 20, 1 << 20);
    if let Some((u, p)) = login {
        o.set_credentials(u, p);
    }
    o
}

/// Connects a client, retrying while the broker is not listening yet (connection
/// refused), and returns once the broker has accepted it (CONNACK).
pub async fn connect(
    addr: SocketAddr,
    id: &str,
    login: Option<(&str, &str)>,
) -> (AsyncClient, EventLoop) {
    let (client, mut ev) = AsyncClient::new(options(addr, id, login), 16);
    tokio::time::timeout(PATIENCE, async {
        loop {
            match ev.poll().await {
                Ok(Event::Incoming(Packet::ConnAck(_))) => return,
                Ok(_) => {}
                Err(ConnectionError::Io(e))
                    if e.kind() == std::io::ErrorKind::ConnectionRefused =>
                {
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
                Err(e) => panic!("{id}: connection failed: {e}"),
            }
        }
    })
    .await
    .unwrap_or_else(|_| panic!("{id}: no CONNACK within {PATIENCE:?}"));
    (client, ev)
}

/// Polls until the connection fails; returns the error (panics if it does not).
pub async fn until_error(ev: &mut EventLoop, what: &str) -> ConnectionError {
    tokio::time::timeout(PATIENCE, async {
        loop {
            if let Err(e) = ev.poll().await {
                return e;
            }
        }
    })
    .await
    .unwrap_or_else(|_| panic!("{what}: the connection was not closed within {PATIENCE:?}"))
}

/// Polls until `pred` holds for an incoming packet.
pub async fn until_incoming(
    ev: &mut EventLoop,
    what: &str,
    pred: impl Fn(&Packet) -> bool,
) -> Packet {
    tokio::time::timeout(PATIENCE, async {
        loop {
            match ev.poll().await {
                Ok(Event::Incoming(p)) if pred(&p) => return p,
                Ok(_) => {}
                Err(e) => panic!("{what}: connection failed: {e}"),
            }
        }
    })
    .await
    .unwrap_or_else(|_| panic!("{what}: not seen within {PATIENCE:?}"))
}

/// Polls until a PUBLISH arrives.
pub async fn next_publish(ev: &mut EventLoop, what: &str) -> Publish {
    match until_incoming(ev, what, |p| matches!(p, Packet::Publish(_))).await {
        Packet::Publish(p) => p,
        _ => unreachable!("filtered above"),
    }
}

/// Polls in the background so a client's requests go out and pings are answered.
pub fn drive(mut ev: EventLoop) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move { while ev.poll().await.is_ok() {} })
}
