//! skymesh autopilot-link: the one MAVLink connection to the flight controller.
//!
//! It connects to the autopilot ([`link`]: serial, UDP or TCP, reconnecting with
//! backoff), identifies it, asks for telemetry rates ([`requests`]), fuses the
//! telemetry into `VehicleState` (once per ATTITUDE) and `VehicleStatus` (on change
//! and at 1 Hz) ([`telemetry`]) and the gimbal and GoPro into `PayloadState` (on change
//! and at 1 Hz) ([`payload`]), executes `VehicleCommand` samples as MAVLink
//! commands, setpoints and GoPro requests ([`commands`]), answers each with a
//! `CommandAck` ([`acks`]), and marks the link down when autopilot heartbeats stop. All iceoryx2
//! calls live in the runtime; this crate only uses its typed publishers and
//! subscribers.
//!
//! | module | role |
//! |---|---|
//! | [`config`] | TOML → [`Settings`] |
//! | [`link`] | transports, reader/writer threads, reconnect |
//! | [`router`] | MAVLink routing table and COMMAND_ACK attribution (pure) |
//! | [`endpoints`] | router endpoints (ground stations): sockets and their tasks |
//! | [`signing`] | MAVLink 2 message signing on router endpoints (framing and signing: `mavlink-frame`) |
//! | [`hub`] | moves frames between autopilot and endpoints; router metrics |
//! | [`telemetry`] | MAVLink → samples (pure) |
//! | [`payload`] | gimbal attitude and GoPro → `PayloadState` (pure) |
//! | [`commands`] | intake checks, `Command` → MAVLink (pure) |
//! | [`acks`] | COMMAND_ACK and GOPRO_SET_RESPONSE matching, retransmission, timeouts (pure) |
//! | [`arbiter`] | authority, freshness, geofence envelope, audit: decides every command (pure) |
//! | [`requests`] | our heartbeat, stream-rate and home requests (pure) |
//! | [`gimbal_v2`] | the vision pipeline's virtual cameras as MAVLink gimbals (pure) |
//! | [`tlog`] | flight logs (`.tlog`) of the autopilot link, rotation and retention |
//! | [`metrics`] | the exported series |
//! | `service` | the event loop tying them together |
#![forbid(unsafe_code)]

pub mod acks;
pub mod arbiter;
pub mod commands;
pub mod config;
pub mod endpoints;
pub mod gimbal_v2;
pub mod hub;
pub mod link;
pub mod metrics;
pub mod payload;
pub mod requests;
pub mod router;
mod service;
pub mod signing;
pub mod telemetry;
pub mod tlog;
mod transport;

use anyhow::Context as _;
use skymesh_ipc_types::{
    topics, ArbiterEvent, AuthorityState, CommandAck, GeofenceSet, PayloadState, ServiceState,
    VehicleCommand, VehicleState, VehicleStatus, VisionControl, VisionReply, VisionState,
};
use skymesh_runtime::{Bus, CancellationToken, Context, Stats};

pub use config::{RawConfig, Settings};

/// How the service reports its lifecycle: to the runtime (heartbeat state, systemd)
/// when run by `service_main`, nowhere in tests.
pub trait Lifecycle: Send {
    /// The bus ports exist; the service is running.
    fn ready(&self);
    /// The autopilot link went up or down (down = degraded).
    fn link_changed(&self, up: bool);
}

impl Lifecycle for Context {
    fn ready(&self) {
        Context::ready(self);
    }

    fn link_changed(&self, up: bool) {
        self.set_state(if up {
            ServiceState::Running
        } else {
            ServiceState::Degraded
        });
    }
}

/// A [`Lifecycle`] that reports nothing (in-process tests, embedding).
#[derive(Debug, Default, Clone, Copy)]
pub struct Detached;

impl Lifecycle for Detached {
    fn ready(&self) {}
    fn link_changed(&self, _up: bool) {}
}

/// The service entry point for `service_main`.
pub async fn run(settings: Settings, ctx: Context) -> anyhow::Result<()> {
    let (bus, stats, shutdown) = (ctx.bus.clone(), ctx.stats.clone(), ctx.shutdown.clone());
    run_with(settings, bus, stats, shutdown, ctx).await
}

/// Runs autopilot-link on `bus` until `shutdown` is cancelled.
///
/// Opens `skymesh/vehicle/{vehicle_id}/{state,status,payload,command_ack,authority,arbiter_events}`
/// as publisher and `.../{command,geofence}` as subscriber, starts the link and returns once both have stopped
/// (well within the runtime's 5 s grace period).
pub async fn run_with(
    settings: Settings,
    bus: Bus,
    stats: Stats,
    shutdown: CancellationToken,
    lifecycle: impl Lifecycle,
) -> anyhow::Result<()> {
    let endpoints = endpoints::Bound::bind(&settings.endpoints).await?;
    run_with_endpoints(settings, endpoints, bus, stats, shutdown, lifecycle).await
}

/// [`run_with`] with the router endpoints already bound (tests bind port 0 and read
/// the ports from [`endpoints::Bound::local_addrs`]).
pub async fn run_with_endpoints(
    settings: Settings,
    endpoints: endpoints::Bound,
    bus: Bus,
    stats: Stats,
    shutdown: CancellationToken,
    lifecycle: impl Lifecycle,
) -> anyhow::Result<()> {
    let id = settings.vehicle_id;
    let ports = service::Ports {
        state: bus
            .publisher::<VehicleState>(&topics::vehicle_state(id))
            .context("opening the vehicle state topic")?,
        status: bus
            .publisher::<VehicleStatus>(&topics::vehicle_status(id))
            .context("opening the vehicle status topic")?,
        payload: bus
            .publisher::<PayloadState>(&topics::vehicle_payload(id))
            .context("opening the vehicle payload topic")?,
        acks: bus
            .publisher::<CommandAck>(&topics::vehicle_command_ack(id))
            .context("opening the command ack topic")?,
        commands: bus
            .subscriber::<VehicleCommand>(&topics::vehicle_command(id))
            .context("opening the vehicle command topic")?,
        authority: bus
            .publisher::<AuthorityState>(&topics::vehicle_authority(id))
            .context("opening the authority topic")?,
        events: bus
            .publisher::<ArbiterEvent>(&topics::vehicle_arbiter_events(id))
            .context("opening the arbiter events topic")?,
        geofence: bus
            .subscriber::<GeofenceSet>(&topics::vehicle_geofence(id))
            .context("opening the geofence topic")?,
    };
    let metrics = metrics::Metrics::new(&stats);
    let audit = arbiter::audit::Audit::new(&stats, id);
    tracing::info!(
        connection = %settings.connection,
        vehicle_id = id,
        system_id = settings.system_id,
        "autopilot-link starting"
    );
    let router_stop = shutdown.child_token();
    let (hub, router_task) = endpoints::start(
        endpoints,
        (settings.system_id, requests::OWN_COMPONENT),
        settings.signing.as_ref(),
        settings.tlog.as_ref(),
        &stats,
        router_stop.clone(),
    );
    let vision_parts = if settings.vision.enabled {
        let (tx, inbox) = tokio::sync::mpsc::channel(service::vision::INBOX);
        hub.attach_local(&settings.vision.components, tx);
        tracing::info!(
            components = ?settings.vision.components,
            stream = settings.vision.stream,
            "virtual gimbals (gimbal protocol v2) enabled"
        );
        Some(service::VisionParts {
            ports: service::vision::VisionPorts {
                state: bus
                    .subscriber::<VisionState>(&topics::vision_state())
                    .context("opening the vision state topic")?,
                control: bus
                    .publisher::<VisionControl>(&topics::vision_control())
                    .context("opening the vision control topic")?,
                reply: bus
                    .subscriber::<VisionReply>(&topics::vision_reply())
                    .context("opening the vision reply topic")?,
                inbox,
            },
            hub: hub.clone(),
            stats: stats.clone(),
        })
    } else {
        None
    };
    // Not a child of `shutdown`: a parent token cancels its children before it marks
    // itself cancelled, so the link task could end (closing its channel) while the
    // service loop still sees `shutdown` as live and reports "the link task ended".
    // The link is stopped explicitly once the service loop has returned.
    let link_stop = CancellationToken::new();
    let (mut events, link_task) = link::spawn(
        link::LinkConfig {
            endpoint: settings.connection.clone(),
            system_id: settings.system_id,
            component_id: requests::OWN_COMPONENT,
            reconnect_min: settings.reconnect_min,
            reconnect_max: settings.reconnect_max,
            silence_reconnect: settings.silence_reconnect,
        },
        metrics.clone(),
        hub,
        link_stop.clone(),
    );
    lifecycle.ready();
    let mut svc = service::Service::new(settings, lifecycle, metrics, audit, ports, vision_parts);
    let result = svc.run(&mut events, &shutdown).await;
    link_stop.cancel();
    // A serial reader thread may be waiting for room in the event channel: close it.
    drop(events);
    if let Err(e) = link_task.await {
        tracing::warn!(error = %e, "link task failed");
    }
    router_stop.cancel();
    if let Err(e) = router_task.await {
        tracing::warn!(error = %e, "router task failed");
    }
    result
}
