//! Every bus call of solo-gateway: the three shot topics, typed.
//!
//! | topic | direction | type |
//! |---|---|---|
//! | `skymesh/shot/requests` | publish (sessions, follow stream) | `ShotRequestSample` |
//! | `skymesh/shot/app_geofence` | publish (sessions: GEOFENCE_SET_DATA) | `AppGeofence` |
//! | `skymesh/shot/app_session` | publish (hub) | `AppSession` |
//! | `skymesh/shot/events` | subscribe (hub) | `ShotEventSample` |

use std::net::SocketAddr;
use std::sync::{Arc, Mutex, PoisonError};

use anyhow::Context as _;
use skymesh_ipc_types::shot_api::request_flags;
use skymesh_ipc_types::{
    topics, AppGeofence, AppSession, FixedStr, ShotEventSample, ShotRequest, ShotRequestSample,
};
use skymesh_runtime::{Bus, IpcError, Publisher, Subscriber};

/// Why a message could not be published.
#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    /// The bus failed: the service cannot work on and stops (and is restarted).
    #[error(transparent)]
    Bus(#[from] IpcError),
}

/// The `from_app` and `app_geofence` publishers, shared by every session and the
/// follow stream.
///
/// One publisher per topic per gateway (the topics allow two, for a restart
/// overlap), so the tasks share them behind mutexes held only for the copy into
/// shared memory.
#[derive(Debug, Clone)]
pub struct FromApp {
    messages: Arc<Mutex<Publisher<ShotRequestSample>>>,
    geofence: Arc<Mutex<Publisher<AppGeofence>>>,
}

impl FromApp {
    /// Publishes one validated app message as the engine's request.
    pub fn publish(
        &self,
        session: u32,
        request: &ShotRequest,
        follow_stream: bool,
    ) -> Result<(), PublishError> {
        let mut m = ShotRequestSample::new(session, request);
        if follow_stream {
            m.flags |= request_flags::FOLLOW_STREAM;
        }
        self.messages
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .publish(m)?;
        Ok(())
    }

    /// Whether a shot engine reads the topic a message goes to (`geofence`: the
    /// `app_geofence` topic of GEOFENCE_SET_DATA, else `requests`): a subscriber
    /// there is the only one that answers the app's requests.
    pub fn engine_reads(&self, geofence: bool) -> bool {
        let subscribers = if geofence {
            self.geofence
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .subscribers()
        } else {
            self.messages
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .subscribers()
        };
        subscribers > 0
    }

    /// Publishes the app's geofence polygons (GEOFENCE_SET_DATA) of `session`.
    pub fn publish_geofence(&self, session: u32, fence: &AppGeofence) -> Result<(), IpcError> {
        let sample = AppGeofence { session, ..*fence };
        self.geofence
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .publish(sample)?;
        Ok(())
    }
}

/// The hub's ports.
#[derive(Debug)]
pub struct Ports {
    pub from_app: FromApp,
    session: Publisher<AppSession>,
    /// Events from the shot engine; the hub translates them and routes them to
    /// the app.
    pub to_app: Subscriber<ShotEventSample>,
}

impl Ports {
    pub fn open(bus: &Bus) -> anyhow::Result<Ports> {
        Ok(Ports {
            from_app: FromApp {
                messages: Arc::new(Mutex::new(
                    bus.publisher::<ShotRequestSample>(&topics::shot_requests())
                        .context("opening the shot requests topic")?,
                )),
                geofence: Arc::new(Mutex::new(
                    bus.publisher::<AppGeofence>(&topics::shot_app_geofence())
                        .context("opening the app_geofence topic")?,
                )),
            },
            session: bus
                .publisher::<AppSession>(&topics::shot_app_session())
                .context("opening the app_session topic")?,
            to_app: bus
                .subscriber::<ShotEventSample>(&topics::shot_events())
                .context("opening the shot events topic")?,
        })
    }

    /// Publishes the app connection state: `session` is the current one, or the last
    /// one when `peer` is `None` (0 = never connected).
    pub fn publish_session(
        &mut self,
        session: u32,
        connected: bool,
        peer: Option<SocketAddr>,
    ) -> Result<(), IpcError> {
        let peer = peer.map(|p| p.to_string()).unwrap_or_default();
        self.session.publish(AppSession {
            session,
            connected: u8::from(connected),
            peer: FixedStr::new(&peer),
            ..AppSession::default()
        })?;
        Ok(())
    }
}
