//! The first request on every protocol, sent the moment the supervisor reports every
//! service `running`: what a client that trusts "ready" does. Used by the e2e test
//! `first_requests` (the harness's mesh) and by `mesh-bench --first-requests` (the
//! shipped deploy/skymesh.toml on its default ports).
//!
//! One request (or one request pair) per protocol, each on its own connection,
//! all at once; each answer is checked for the protocol's correct reply and timed
//! from the moment the mesh reported running.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail, Context, Result};
use digiview_proto::{
    CamTargeting, Frame, GetRequest, MessageType, Param, ParamType, StreamName, FRAME_LEN,
};
use gc_proto::{NetCmdType, Record, RECORD_LEN};
use imc_proto::Message as Imc;
use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink::{Connectable, Connection, MavConnection, UdpConfig, UdpMode};
use serde_json::json;
use skymesh_dji_gateway::cloud::Cloud;
use skymesh_imc_gateway::client::ImcClient;
use skymesh_solo_gateway::client::AppClient;
use solo_proto::{GeofenceData, SoloMessage};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

use crate::HOME;

/// The IMC gateway's address (deploy/imc-gateway.toml's default).
const IMC_GATEWAY_ID: u16 = 0x2c01;

/// Where each protocol's first request goes.
#[derive(Debug, Clone)]
pub struct Targets {
    /// Solo app TCP.
    pub solo: SocketAddr,
    /// The MQTT broker the DJI gateway uses, and the gateway's serial number.
    pub mqtt: SocketAddr,
    pub dji_sn: String,
    /// DigiView TCP.
    pub digiview: SocketAddr,
    /// GroundControl state server TCP.
    pub gc: SocketAddr,
    /// IMC gateway UDP.
    pub imc: SocketAddr,
}

/// One protocol's first request: what was asked, how long after "running" the
/// (last) answer came, and the answer or what was wrong with it.
#[derive(Debug)]
pub struct Answer {
    pub protocol: &'static str,
    pub request: &'static str,
    pub after: Duration,
    pub outcome: Result<String>,
}

/// A ground station's MAVLink endpoint, bound before the mesh starts (autopilot-link's
/// router sends to it: `udpout:127.0.0.1:<port>`).
pub struct GcsEndpoint {
    conn: Connection<MavMessage>,
}

impl std::fmt::Debug for GcsEndpoint {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("GcsEndpoint")
    }
}

impl GcsEndpoint {
    /// Listens on 127.0.0.1:`port` (0 is not possible here: the router is told a port).
    pub fn bind(port: u16) -> Result<GcsEndpoint> {
        let conn = UdpConfig::new(format!("127.0.0.1:{port}"), UdpMode::Udpin)
            .read_timeout(Duration::from_millis(50))
            .connect::<MavMessage>()
            .context("binding the ground station's MAVLink endpoint")?;
        Ok(GcsEndpoint { conn })
    }

    /// The first HEARTBEAT of vehicle `system`'s autopilot (component 1) within `limit` of `t0`.
    fn heartbeat(&self, system: u8, t0: Instant, limit: Duration) -> Result<String> {
        while t0.elapsed() < limit {
            if let Ok((h, MavMessage::HEARTBEAT(hb))) = self.conn.recv() {
                if h.system_id == u32::from(system) && h.component_id == 1 {
                    return Ok(format!(
                        "HEARTBEAT from {}/{} ({:?})",
                        h.system_id, h.component_id, hb.mavtype
                    ));
                }
            }
        }
        bail!("no HEARTBEAT of system {system}")
    }
}

/// Sends every protocol's first request at once (the clock starts at `t0`, the moment
/// the mesh reported running) and returns every answer, each waited for at most
/// `limit` after `t0`.
pub async fn send_all(
    targets: &Targets,
    gcs: GcsEndpoint,
    t0: Instant,
    limit: Duration,
) -> Vec<Answer> {
    let timed = |protocol, request, (outcome, after): (Result<String>, Duration)| Answer {
        protocol,
        request,
        after,
        outcome,
    };
    let mavlink = tokio::task::spawn_blocking(move || (gcs.heartbeat(1, t0, limit), t0.elapsed()));
    let ((solo_shot, solo_bad, solo_good), dji, (dv_status, dv_targeting), gc, imc) = tokio::join!(
        solo(targets.solo, t0, limit),
        within(t0, limit, dji_request(targets.mqtt, &targets.dji_sn)),
        digiview(targets.digiview, t0, limit),
        within(t0, limit, gc_ping(targets.gc)),
        within(t0, limit, imc_query(targets.imc)),
    );
    let mavlink = mavlink.await.unwrap_or_else(|e| {
        (
            Err(anyhow!("the ground station thread failed: {e}")),
            t0.elapsed(),
        )
    });
    vec![
        solo_shot,
        solo_bad,
        solo_good,
        timed("dji", "services flight_authority_grab", dji),
        dv_status,
        dv_targeting,
        timed("groundcontrol", "PING_REQUEST", gc),
        timed("imc", "QueryPowerChannelState", imc),
        timed("mavlink", "HEARTBEAT at the GCS endpoint", mavlink),
    ]
}

/// `f`, or an error once `limit` after `t0` has passed.
async fn within<F: std::future::Future<Output = Result<String>>>(
    t0: Instant,
    limit: Duration,
    f: F,
) -> (Result<String>, Duration) {
    let left = limit.saturating_sub(t0.elapsed());
    let r = tokio::time::timeout(left, f)
        .await
        .unwrap_or_else(|_| Err(anyhow!("no answer within {limit:?}")));
    (r, t0.elapsed())
}

/// One app connection (the gateway serves one app per address; a second connection
/// replaces the first): the shot the engine says is current (sent to every app on
/// connect: GET_CURRENT_SHOT), then a GEOFENCE_SET_DATA whose `coord` and `subCoord`
/// lists differ in length (answered `valid = false`), then a valid ±60 m keep-in
/// around home (answered `valid = true` once the arbiter took it).
async fn solo(addr: SocketAddr, t0: Instant, limit: Duration) -> (Answer, Answer, Answer) {
    let answer = |request, outcome| Answer {
        protocol: "solo",
        request,
        after: t0.elapsed(),
        outcome,
    };
    let requests = [
        "GET_CURRENT_SHOT on connect",
        "GEOFENCE_SET_DATA malformed",
        "GEOFENCE_SET_DATA valid",
    ];
    let mut app = match tokio::time::timeout(limit, AppClient::connect(addr)).await {
        Ok(Ok(a)) => a,
        failed => {
            let e = format!("connect: {failed:?}");
            return (
                answer(requests[0], Err(anyhow!("{e}"))),
                answer(requests[1], Err(anyhow!("{e}"))),
                answer(requests[2], Err(anyhow!("{e}"))),
            );
        }
    };
    let left = || limit.saturating_sub(t0.elapsed());
    let shot = match app
        .recv_until(left(), |m| matches!(m, SoloMessage::GetCurrentShot(_)))
        .await
    {
        Some(m) => Ok(format!("{m:?}")),
        None => Err(anyhow!("no GET_CURRENT_SHOT within {limit:?}")),
    };
    let shot = answer(requests[0], shot);
    let is_ack = |m: &SoloMessage| matches!(m, SoloMessage::GeofenceSetAck { .. });
    let corner = |n: f64, e: f64| {
        [
            HOME[0] + n / 111_320.0,
            HOME[1] + e / (111_320.0 * HOME[0].to_radians().cos()),
        ]
    };
    let square = |d: f64| vec![corner(-d, -d), corner(-d, d), corner(d, d), corner(d, -d)];
    // Not encodable through `SoloMessage` (its encoder checks the sizes): raw TLV.
    let json = json!({ "coord": [square(60.0)], "subCoord": [], "type": [0] }).to_string();
    let mut tlv = solo_proto::ids::GEOFENCE_SET_DATA.to_le_bytes().to_vec();
    tlv.extend_from_slice(&(json.len() as u32).to_le_bytes());
    tlv.extend_from_slice(json.as_bytes());
    let bad = async {
        app.send_raw(&tlv).await?;
        match app.recv_until(left(), is_ack).await {
            Some(SoloMessage::GeofenceSetAck { valid: false, .. }) => Ok("valid = false".into()),
            Some(m) => bail!("answered {m:?}"),
            None => bail!("no GEOFENCE_SET_ACK within {limit:?}"),
        }
    }
    .await;
    let bad = answer(requests[1], bad);
    let good = async {
        app.send(&SoloMessage::GeofenceSetData(GeofenceData {
            coord: vec![square(60.0)],
            sub_coord: vec![square(55.0)],
            kinds: vec![0],
        }))
        .await?;
        match app.recv_until(left(), is_ack).await {
            Some(SoloMessage::GeofenceSetAck {
                count: 1,
                valid: true,
            }) => Ok("count 1, valid = true".into()),
            Some(m) => bail!("answered {m:?}"),
            None => bail!("no GEOFENCE_SET_ACK within {limit:?}"),
        }
    }
    .await;
    (shot, bad, answer(requests[2], good))
}

/// A cloud grabs flight authority: `services_reply` result 0 (the arbiter granted it).
async fn dji_request(mqtt: SocketAddr, sn: &str) -> Result<String> {
    let mut cloud = Cloud::connect(mqtt, sn).await?;
    cloud.set_reply_timeout(Duration::from_secs(60));
    let result = cloud
        .call_result("flight_authority_grab", json!({}))
        .await?;
    if result != 0 {
        bail!("result {result}");
    }
    Ok("result 0".into())
}

/// GET SYSTEM_STATUS (CURRENT, not UNKNOWN; idle or running), and on a second
/// connection SET CAM_TARGETING then an immediate GET that reads the value back.
async fn digiview(addr: SocketAddr, t0: Instant, limit: Duration) -> (Answer, Answer) {
    let answer = |request, outcome| Answer {
        protocol: "digiview",
        request,
        after: t0.elapsed(),
        outcome,
    };
    let left = || limit.saturating_sub(t0.elapsed());
    let status = async {
        let mut s = TcpStream::connect(addr).await?;
        let r = exchange(
            &mut s,
            &Frame::new(MessageType::Get, ParamType::SystemStatus),
        )
        .await?;
        match (r.message_type, Param::decode(r.param_type, &r.data)) {
            (MessageType::Current, Ok(Param::SystemStatus(st))) if st.status <= 1 => {
                Ok(format!("CURRENT status {}", st.status))
            }
            (t, p) => bail!("answered {t:?} {p:?}"),
        }
    };
    let status = answer(
        "GET SYSTEM_STATUS",
        tokio::time::timeout(left(), status)
            .await
            .unwrap_or_else(|_| Err(anyhow!("no answer within {limit:?}"))),
    );
    let targeting = async {
        let mut s = TcpStream::connect(addr).await?;
        let stream = StreamName::new("main").map_err(|e| anyhow!("{e:?}"))?;
        let want = CamTargeting {
            stream,
            cam: 0,
            mode: 0,
            yaw: 1.5,
            pitch: -0.5,
            ..Default::default()
        };
        let set = Frame::with_param(MessageType::Set, &Param::CamTargeting(want));
        let r = exchange(&mut s, &set).await?;
        if r.message_type != MessageType::Acknowledgement {
            bail!("SET answered {:?}", r.message_type);
        }
        let mut get = Frame::new(MessageType::Get, ParamType::CamTargeting);
        get.data = GetRequest {
            stream,
            cam: Some(0),
        }
        .encode();
        let r = exchange(&mut s, &get).await?;
        match Param::decode(r.param_type, &r.data) {
            Ok(Param::CamTargeting(got))
                if r.message_type == MessageType::Current
                    && (got.yaw - want.yaw).abs() < 1e-3
                    && (got.pitch - want.pitch).abs() < 1e-3 =>
            {
                Ok(format!(
                    "ACK, then yaw {:.3} pitch {:.3}",
                    got.yaw, got.pitch
                ))
            }
            other => bail!("GET after the ACK answered {:?} {other:?}", r.message_type),
        }
    };
    let targeting = answer(
        "SET CAM_TARGETING, GET",
        tokio::time::timeout(left(), targeting)
            .await
            .unwrap_or_else(|_| Err(anyhow!("no answer within {limit:?}"))),
    );
    (status, targeting)
}

/// One DigiView frame out, the next frame in.
async fn exchange(s: &mut TcpStream, f: &Frame) -> Result<Frame> {
    s.write_all(&f.encode()).await?;
    let mut b = [0u8; FRAME_LEN];
    s.read_exact(&mut b).await?;
    Frame::decode(&b).map_err(|e| anyhow!("invalid frame ({e}): {b:?}"))
}

/// PING_REQUEST, answered by PING_RESPONSE echoing the sequence.
async fn gc_ping(addr: SocketAddr) -> Result<String> {
    let mut s = TcpStream::connect(addr).await?;
    s.write_all(&Record::ping_request(4711, 0.0, 0.0).encode())
        .await?;
    let mut buf = Vec::new();
    loop {
        while buf.len() >= RECORD_LEN {
            let r = Record::from_prefix(&buf).ok_or_else(|| anyhow!("bad record"))?;
            buf.drain(..RECORD_LEN);
            if r.kind == NetCmdType::PingResponse.id() {
                if r.int1 != 4711 {
                    bail!("PING_RESPONSE for sequence {}", r.int1);
                }
                return Ok("PING_RESPONSE".into());
            }
        }
        let mut chunk = [0u8; 1024];
        let n = s.read(&mut chunk).await?;
        if n == 0 {
            bail!("connection closed without PING_RESPONSE");
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

/// QueryPowerChannelState, answered by one PowerChannelState per channel.
async fn imc_query(addr: SocketAddr) -> Result<String> {
    let mut peer = ImcClient::connect(addr).await?;
    peer.identity.dst = IMC_GATEWAY_ID;
    match peer
        .request(&Imc::QueryPowerChannelState, Duration::from_secs(60), |m| {
            matches!(m, Imc::PowerChannelState { .. })
        })
        .await?
    {
        Some(Imc::PowerChannelState { name, state }) => {
            Ok(format!("PowerChannelState {name} {state:?}"))
        }
        Some(m) => bail!("answered {m:?}"),
        None => bail!("no PowerChannelState"),
    }
}

/// One line per answer, for a test's or a benchmark's output.
pub fn report(answers: &[Answer]) -> String {
    let mut out = String::new();
    for a in answers {
        let what = match &a.outcome {
            Ok(s) => format!("ok: {s}"),
            Err(e) => format!("FAILED: {e:#}"),
        };
        out += &format!(
            "{:<14} {:<34} {:>8.1} ms  {what}\n",
            a.protocol,
            a.request,
            a.after.as_secs_f64() * 1e3
        );
    }
    out
}
