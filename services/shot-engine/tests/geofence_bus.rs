//! The geofence path through real iceoryx2 shared memory: the app's polygons arrive
//! as an `AppGeofence` (solo-gateway's translation of GEOFENCE_SET_DATA), the fence
//! goes to the arbiter as a `GeofenceSet`, and the app's answer follows the
//! arbiter's decision event (played by the test). Waits are bounded by generous
//! timeouts; nothing asserts timing.

mod common;

use skymesh_ipc_types::shot_api::{ShotEvent, ShotRequest};
use skymesh_ipc_types::{
    topics, AppGeofence, AppSession, ArbiterEvent, ArbiterEventKind, CommandSource, FenceKind,
    GeofenceSet, ServiceId,
};
use skymesh_ipc_types::{ShotEventSample, ShotRequestSample};
use skymesh_runtime::{Bus, Publisher, Stats, Subscriber};

use common::{app_msg, settings, unique_domain, Engine, PATIENCE, VEHICLE};

async fn next<T: skymesh_ipc_types::Sample>(sub: &mut Subscriber<T>, what: &str) -> T {
    sub.recv_timeout(PATIENCE)
        .await
        .unwrap()
        .unwrap_or_else(|| panic!("no {what} within {PATIENCE:?}"))
}

/// The next geofence answer or error for the app (skipping what it gets on connect).
async fn next_answer(to_app: &mut Subscriber<ShotEventSample>) -> ShotEvent {
    loop {
        let m = next(to_app, "app message").await;
        let msg = m.event().unwrap();
        if matches!(msg, ShotEvent::GeofenceSetAck { .. } | ShotEvent::Error(_)) {
            return msg;
        }
    }
}

/// The arbiter's decision on `set`.
fn decide(events: &mut Publisher<ArbiterEvent>, set: &GeofenceSet, kind: ArbiterEventKind) {
    events
        .publish(ArbiterEvent {
            vehicle_id: set.vehicle_id,
            kind: kind.to_wire(),
            source: set.source,
            request_id: set.request_id,
            ..ArbiterEvent::default()
        })
        .unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fence_then_a_clear_reach_the_arbiter_in_the_order_the_app_sent_them() {
    let dir = tempfile::tempdir().unwrap();
    let domain = unique_domain();
    let bus = Bus::open(&domain, "tool", ServiceId::Tool, 0, Stats::new()).expect("tool bus");
    let mut fences = bus
        .publisher::<AppGeofence>(&topics::shot_app_geofence())
        .unwrap();
    let mut from_app = bus
        .publisher::<ShotRequestSample>(&topics::shot_requests())
        .unwrap();
    let mut session = bus
        .publisher::<AppSession>(&topics::shot_app_session())
        .unwrap();
    let mut to_app = bus
        .subscriber::<ShotEventSample>(&topics::shot_events())
        .unwrap();
    let mut arbiter = bus
        .subscriber::<GeofenceSet>(&topics::vehicle_geofence(VEHICLE))
        .unwrap();
    let mut events = bus
        .publisher::<ArbiterEvent>(&topics::vehicle_arbiter_events(VEHICLE))
        .unwrap();
    let engine = Engine::start(&domain, settings(dir.path())).await;

    session
        .publish(AppSession {
            session: 1,
            connected: 1,
            ..AppSession::default()
        })
        .unwrap();
    let square = [
        [-35.36, 149.16],
        [-35.36, 149.17],
        [-35.37, 149.17],
        [-35.37, 149.16],
    ];
    let inner = [
        [-35.361, 149.161],
        [-35.361, 149.169],
        [-35.369, 149.169],
        [-35.369, 149.161],
    ];
    let fence = AppGeofence::new(1, [(0u8, &square[..], &inner[..])].into_iter()).unwrap();
    // Back to back: both are pending when the engine wakes (or arrive in order).
    fences.publish(fence).unwrap();
    from_app
        .publish(app_msg(&ShotRequest::GeofenceClear))
        .unwrap();

    // The arbiter's topic holds the latest fence: when both requests were handled
    // in one wake only the clear is published (and its decision answers both);
    // else the fence, then the clear.
    let mut set = next(&mut arbiter, "GeofenceSet").await;
    decide(&mut events, &set, ArbiterEventKind::GeofenceUpdated);
    if set.enabled == 1 {
        assert_eq!(set.header.service_id(), Ok(ServiceId::ShotEngine));
        assert_eq!(
            (set.vehicle_id, set.source),
            (VEHICLE, CommandSource::ShotEngine.to_wire())
        );
        assert_eq!(set.polygons().unwrap(), [(FenceKind::KeepIn, &square[..])]);
        set = next(&mut arbiter, "GeofenceSet").await;
        decide(&mut events, &set, ArbiterEventKind::GeofenceUpdated);
    }
    assert_eq!(
        (set.vehicle_id, set.enabled, set.polygon_count, set.source),
        (VEHICLE, 0, 0, CommandSource::ShotEngine.to_wire())
    );
    assert_eq!(
        next_answer(&mut to_app).await,
        ShotEvent::GeofenceSetAck {
            count: 1,
            valid: true
        }
    );
    assert_eq!(
        next_answer(&mut to_app).await,
        ShotEvent::GeofenceSetAck {
            count: 0,
            valid: true
        }
    );
    // Alone, the fence goes to the arbiter whole; refused there, the app hears so.
    fences.publish(fence).unwrap();
    let set = next(&mut arbiter, "GeofenceSet").await;
    assert_eq!(set.header.service_id(), Ok(ServiceId::ShotEngine));
    assert_eq!(set.enabled, 1);
    assert_eq!(set.polygons().unwrap(), [(FenceKind::KeepIn, &square[..])]);
    decide(&mut events, &set, ArbiterEventKind::GeofenceInvalid);
    assert_eq!(
        next_answer(&mut to_app).await,
        ShotEvent::GeofenceSetAck {
            count: 0,
            valid: false
        }
    );
    assert!(matches!(
        next_answer(&mut to_app).await,
        ShotEvent::Error(_)
    ));
    fences.publish(fence).unwrap();
    let set = next(&mut arbiter, "GeofenceSet").await;
    decide(&mut events, &set, ArbiterEventKind::GeofenceUpdated);
    assert_eq!(
        next_answer(&mut to_app).await,
        ShotEvent::GeofenceSetAck {
            count: 1,
            valid: true
        }
    );
    assert_eq!(
        engine
            .stats
            .gauge("skymesh_shot_geofence_polygons", &[])
            .get(),
        1.0
    );
    engine.stop().await;
    drop((fences, from_app, session, to_app, arbiter, events, bus));
    domain.remove_leftover_files();
}
