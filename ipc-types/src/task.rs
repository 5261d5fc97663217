//! Tasks asked of the shot engine's task runner by a gateway: take off to a
//! point, fly to a point (stop, update), orbit a point of interest (speed, exit),
//! sweep the gimbal through a panorama (stop). Protocol-neutral: a gateway
//! translates its protocol's requests into [`TaskRequest`]s and the runner's
//! [`TaskEvent`]s back into its protocol's replies and events (the DJI gateway:
//! services replies, `*_progress`, `poi_status_notify` and
//! `camera_photo_take_progress` events).
//!
//! Every request is answered by one [`TaskEventKind::Reply`] with its `request_id`
//! and a [`TaskResult`]. A task started by a request reports under that request's
//! id ([`TaskEventKind::Flight`], [`TaskEventKind::Poi`], [`TaskEventKind::Pano`])
//! until a terminal status.
//! The runner commands the vehicle through the arbiter as `source` (the gateway's
//! own [`crate::CommandSource`]): authority, refusals and acks are the gateway's.
//!
//! Heights are metres above home; conversions (DJI's ellipsoid heights) stay in
//! the gateway.

use iceoryx2::prelude::ZeroCopySend;

use crate::header::SampleHeader;
use crate::wire_enum;

wire_enum! {
    /// What a [`TaskRequest`] asks.
    pub enum TaskRequestKind: u8 {
        /// Arm and climb to `climb_alt_rel_m` if on the ground (or climb there if
        /// lower), then fly to the target.
        Takeoff = 1 => "takeoff",
        /// Fly a flying vehicle to the target.
        FlyTo = 2 => "fly_to",
        /// Brake and end the running takeoff / fly-to task.
        FlyToStop = 3 => "fly_to_stop",
        /// A new target (and speed) for the running takeoff / fly-to task.
        FlyToUpdate = 4 => "fly_to_update",
        /// Orbit the target point at `speed_mps` from where the vehicle is.
        PoiEnter = 5 => "poi_enter",
        /// A new orbit speed (`speed_mps`) for the running orbit.
        PoiSpeed = 6 => "poi_speed",
        /// Brake and end the running orbit.
        PoiExit = 7 => "poi_exit",
        /// Sweep the gimbal from where it points through `pano_stations` stations
        /// at `pano_pitch_deg`, one photo each, then back (payload authority only:
        /// the aircraft does not move).
        PanoStart = 8 => "pano_start",
        /// End the running panorama (status `Stopped`; the gimbal goes back).
        PanoStop = 9 => "pano_stop",
    }
}

wire_enum! {
    /// The outcome a [`TaskEventKind::Reply`] or a terminal event carries.
    pub enum TaskResult: u8 {
        Ok = 0 => "ok",
        /// A value out of range (the arbiter's `InvalidParameter`, or a command the
        /// runner could not build).
        InvalidParameter = 1 => "invalid_parameter",
        /// The bus refused a sample.
        Internal = 2 => "internal",
        /// The link to the autopilot is down or a command went unacknowledged.
        VehicleUnavailable = 3 => "vehicle_unavailable",
        /// `source` does not hold flight authority (or lost it).
        NoFlightAuthority = 4 => "no_flight_authority",
        /// `source` does not hold payload authority.
        NoPayloadAuthority = 5 => "no_payload_authority",
        /// The vehicle's state does not allow it (not flying, no position, mode).
        WrongState = 6 => "wrong_state",
        /// Refused by the arbiter for another reason (geofence, priority).
        Refused = 7 => "refused",
        /// No running task to stop or update.
        NoTask = 8 => "no_task",
        /// The payload cannot do it (the arbiter's `Unsupported` for a payload
        /// command).
        PayloadUnsupported = 9 => "payload_unsupported",
    }
}

wire_enum! {
    /// What a [`TaskEvent`] reports.
    pub enum TaskEventKind: u8 {
        /// The answer to the request `request_id` (`result`).
        Reply = 1 => "reply",
        /// Progress of the takeoff / fly-to task started by `request_id`.
        Flight = 2 => "flight",
        /// Status of the orbit started by `request_id`.
        Poi = 3 => "poi",
        /// Progress of the panorama started by `request_id`.
        Pano = 4 => "pano",
    }
}

wire_enum! {
    /// `status` of a [`TaskEventKind::Flight`] event.
    pub enum FlightTaskStatus: u8 {
        /// A takeoff was accepted (once, before any progress).
        Ready = 1 => "ready",
        /// Periodic progress.
        Progress = 2 => "progress",
        /// The target was reached (terminal for a fly-to).
        Arrived = 3 => "arrived",
        /// A takeoff is complete (after `Arrived`, terminal).
        Finished = 4 => "finished",
        /// Ended without reaching the target (`result` says why; terminal).
        Failed = 5 => "failed",
        /// Stopped, pre-empted or taken over (terminal).
        Cancelled = 6 => "cancelled",
    }
}

wire_enum! {
    /// `status` of a [`TaskEventKind::Poi`] event.
    pub enum PoiTaskStatus: u8 {
        /// Orbiting (after the start and after each speed change).
        InProgress = 1 => "in_progress",
        /// Ended on request or by a new task (terminal).
        Ended = 2 => "ended",
        /// Could not start, or had to end (`reason`; terminal).
        Failed = 3 => "failed",
    }
}

wire_enum! {
    /// Why an orbit could not start or had to end (`reason` of a Poi event).
    pub enum PoiReason: u8 {
        Normal = 0 => "normal",
        /// No fresh position.
        PositioningFailure = 1 => "positioning_failure",
        /// The vehicle is not flying.
        NotTakenOff = 2 => "not_taken_off",
        /// Not in GUIDED, or `source` lost flight authority.
        FlightModeError = 3 => "flight_mode_error",
        /// The vehicle returns, lands or flies manually.
        UnavailableMode = 4 => "unavailable_mode",
        /// The autopilot link is down.
        LinkLost = 5 => "link_lost",
    }
}

wire_enum! {
    /// `status` of a [`TaskEventKind::Pano`] event.
    pub enum PanoTaskStatus: u8 {
        /// Started (0 photos), and after each photo.
        InProgress = 1 => "in_progress",
        /// Every photo taken and the gimbal back at its start (terminal; also when
        /// the gimbal did not get back: the photos exist).
        Done = 2 => "done",
        /// Ended early (`result` says why; terminal).
        Failed = 3 => "failed",
        /// Ended by a `PanoStop` (terminal; not an error).
        Stopped = 4 => "stopped",
    }
}

/// A point: WGS-84 latitude/longitude, metres above home.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct TaskPoint {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub alt_rel_m: f32,
    pub reserved: u32,
}
crate::assert_layout!(TaskPoint, size = 24, align = 8);

/// One request to the task runner.
///
/// Topic: [`crate::topics::task_request`] (gateways write, the shot engine reads).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.TaskRequest.v2")]
#[repr(C)]
pub struct TaskRequest {
    pub header: SampleHeader,
    /// Chosen by the requester, echoed by the events answering it.
    pub request_id: u32,
    pub vehicle_id: u8,
    /// [`TaskRequestKind`] as stored on the wire.
    pub kind: u8,
    /// [`crate::CommandSource`] the runner commands the vehicle as.
    pub source: u8,
    pub reserved: u8,
    /// Takeoff / FlyTo / FlyToUpdate target; PoiEnter: the point.
    pub target: TaskPoint,
    /// Takeoff: climb to this height above home first; NaN otherwise.
    pub climb_alt_rel_m: f32,
    /// Flight: the horizontal speed, NaN for the autopilot's default. Poi: the
    /// orbit's tangential speed (positive counter-clockwise seen from above).
    pub speed_mps: f32,
    /// Poi: the largest |speed| (the orbit's speed limit).
    pub max_speed_mps: f32,
    /// Flight: the target counts as reached within this 3-D distance, m.
    pub arrival_radius_m: f32,
    /// Flight: a task whose remaining distance has not shrunk for this long fails, s.
    pub stall_timeout_s: f32,
    /// Flight: period of the `Progress` events, ms.
    pub progress_interval_ms: u32,
    /// How long the runner waits for each command's acknowledgement, ms (the
    /// requester's own command timeout: its refusals read the same).
    pub ack_timeout_ms: u32,
    /// PanoStart: the stations' gimbal pitch, degrees (down negative).
    pub pano_pitch_deg: f32,
    /// PanoStart: the gimbal must reach each station within this, ms.
    pub pano_settle_timeout_ms: u32,
    /// PanoStart: photos per full circle (stations `360/n`° apart in yaw).
    pub pano_stations: u8,
    /// PanoStart: 1 to send `ClearRoi` first (an ROI would hold the gimbal).
    pub pano_clear_roi: u8,
    pub reserved2: [u8; 2],
}
crate::assert_layout!(TaskRequest, size = 24 + 8 + 24 + 40, align = 8);

impl TaskRequest {
    pub fn kind(&self) -> Result<TaskRequestKind, crate::UnknownValue> {
        TaskRequestKind::try_from(self.kind)
    }

    pub fn source(&self) -> Result<crate::CommandSource, crate::UnknownValue> {
        crate::CommandSource::try_from(self.source)
    }

    /// `speed_mps` if it is a number.
    pub fn speed(&self) -> Option<f32> {
        self.speed_mps.is_finite().then_some(self.speed_mps)
    }

    /// `climb_alt_rel_m` if it is a number.
    pub fn climb(&self) -> Option<f32> {
        self.climb_alt_rel_m
            .is_finite()
            .then_some(self.climb_alt_rel_m)
    }
}

/// Most points a Flight event lists (a takeoff's climb point and its target).
pub const TASK_MAX_POINTS: usize = 2;

/// A reply or a task's progress, published by the task runner.
///
/// Topic: [`crate::topics::task_event`]. A requester keeps the events whose
/// `source` is its own and matches `request_id`.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.TaskEvent.v2")]
#[repr(C)]
pub struct TaskEvent {
    pub header: SampleHeader,
    /// The request answered, or the request that started the task reporting.
    pub request_id: u32,
    pub vehicle_id: u8,
    /// [`TaskEventKind`] as stored on the wire.
    pub kind: u8,
    /// [`crate::CommandSource`] of the request.
    pub source: u8,
    /// [`TaskResult`] as stored on the wire.
    pub result: u8,
    /// [`FlightTaskStatus`], [`PoiTaskStatus`] or [`PanoTaskStatus`] as stored on
    /// the wire; 0 for a reply.
    pub status: u8,
    /// Poi: [`PoiReason`] as stored on the wire.
    pub reason: u8,
    /// Flight: the point being flown to (takeoff: 0 the climb point, 1 the target).
    pub way_point_index: u8,
    /// Flight: how many of `points` hold values.
    pub point_count: u8,
    /// Pano: photos taken so far, of `pano_stations`.
    pub pano_photos: u8,
    /// Pano: the panorama's photos (stations).
    pub pano_stations: u8,
    /// Pano: percent done; 100 only at `Done` (the return to the start is the
    /// last step).
    pub pano_percent: u8,
    pub reserved: u8,
    /// Flight: metres still to fly, and at the present speed seconds.
    pub remaining_distance_m: f32,
    pub remaining_time_s: f32,
    /// Poi: the orbit's radius, m, speed and speed limit, m/s.
    pub circle_radius_m: f32,
    pub circle_speed_mps: f32,
    pub max_circle_speed_mps: f32,
    pub reserved2: u32,
    /// Flight: the points still to fly, the current leg's end first.
    pub points: [TaskPoint; TASK_MAX_POINTS],
}
crate::assert_layout!(TaskEvent, size = 24 + 16 + 24 + 48, align = 8);

impl TaskEvent {
    /// The reply to `request`.
    pub fn reply(request: &TaskRequest, result: TaskResult) -> Self {
        TaskEvent {
            request_id: request.request_id,
            vehicle_id: request.vehicle_id,
            kind: TaskEventKind::Reply.to_wire(),
            source: request.source,
            result: result.to_wire(),
            ..Default::default()
        }
    }

    pub fn kind(&self) -> Result<TaskEventKind, crate::UnknownValue> {
        TaskEventKind::try_from(self.kind)
    }

    pub fn result(&self) -> Result<TaskResult, crate::UnknownValue> {
        TaskResult::try_from(self.result)
    }

    pub fn flight_status(&self) -> Result<FlightTaskStatus, crate::UnknownValue> {
        FlightTaskStatus::try_from(self.status)
    }

    pub fn poi_status(&self) -> Result<PoiTaskStatus, crate::UnknownValue> {
        PoiTaskStatus::try_from(self.status)
    }

    pub fn pano_status(&self) -> Result<PanoTaskStatus, crate::UnknownValue> {
        PanoTaskStatus::try_from(self.status)
    }

    pub fn poi_reason(&self) -> Result<PoiReason, crate::UnknownValue> {
        PoiReason::try_from(self.reason)
    }

    /// The listed points.
    pub fn points(&self) -> &[TaskPoint] {
        &self.points[..usize::from(self.point_count).min(TASK_MAX_POINTS)]
    }

    /// Lists `points` (at most [`TASK_MAX_POINTS`]; the rest are dropped).
    pub fn set_points(&mut self, points: &[TaskPoint]) {
        let n = points.len().min(TASK_MAX_POINTS);
        self.points[..n].copy_from_slice(&points[..n]);
        self.point_count = n as u8;
    }
}

crate::impl_sample!(TaskRequest, TaskEvent);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::CommandSource;

    #[test]
    fn a_reply_answers_its_request() {
        let req = TaskRequest {
            request_id: 7,
            vehicle_id: 1,
            kind: TaskRequestKind::FlyTo.to_wire(),
            source: CommandSource::DjiDrc.to_wire(),
            climb_alt_rel_m: f32::NAN,
            speed_mps: 5.0,
            ..Default::default()
        };
        assert_eq!(req.kind(), Ok(TaskRequestKind::FlyTo));
        assert_eq!(req.source(), Ok(CommandSource::DjiDrc));
        assert_eq!((req.climb(), req.speed()), (None, Some(5.0)));
        let r = TaskEvent::reply(&req, TaskResult::NoTask);
        assert_eq!((r.request_id, r.vehicle_id, r.source), (7, 1, req.source));
        assert_eq!(r.kind(), Ok(TaskEventKind::Reply));
        assert_eq!(r.result(), Ok(TaskResult::NoTask));
    }

    #[test]
    fn points_are_capped_and_counted() {
        let p = |lat| TaskPoint {
            lat_deg: lat,
            ..Default::default()
        };
        let mut e = TaskEvent::default();
        assert!(e.points().is_empty());
        e.set_points(&[p(1.0), p(2.0), p(3.0)]);
        assert_eq!(e.points(), &[p(1.0), p(2.0)]);
        e.point_count = 200;
        assert_eq!(e.points().len(), TASK_MAX_POINTS, "a bad count is capped");
    }

    #[test]
    fn unknown_wire_values_are_refused() {
        assert!(TaskRequestKind::try_from(0).is_err());
        assert!(TaskResult::try_from(10).is_err());
        let e = TaskEvent {
            status: 9,
            reason: 9,
            ..Default::default()
        };
        assert!(e.flight_status().is_err() && e.poi_status().is_err() && e.poi_reason().is_err());
        assert!(e.pano_status().is_err());
        assert_eq!(PoiReason::try_from(5), Ok(PoiReason::LinkLost));
        assert!(TaskRequestKind::try_from(10).is_err());
        assert!(TaskEventKind::try_from(5).is_err());
    }

    #[test]
    fn a_panorama_request_and_its_progress() {
        let req = TaskRequest {
            request_id: 3,
            vehicle_id: 1,
            kind: TaskRequestKind::PanoStart.to_wire(),
            source: CommandSource::DjiDrc.to_wire(),
            pano_pitch_deg: -10.0,
            pano_settle_timeout_ms: 4000,
            pano_stations: 8,
            pano_clear_roi: 1,
            ..Default::default()
        };
        assert_eq!(req.kind(), Ok(TaskRequestKind::PanoStart));
        assert_eq!(
            TaskRequestKind::try_from(9),
            Ok(TaskRequestKind::PanoStop),
            "the wire values of the panorama kinds"
        );
        let e = TaskEvent {
            kind: TaskEventKind::Pano.to_wire(),
            status: PanoTaskStatus::Stopped.to_wire(),
            pano_photos: 2,
            pano_stations: 8,
            pano_percent: 22,
            ..TaskEvent::reply(&req, TaskResult::Ok)
        };
        assert_eq!(e.kind(), Ok(TaskEventKind::Pano));
        assert_eq!(e.pano_status(), Ok(PanoTaskStatus::Stopped));
        assert_eq!((e.request_id, e.source), (3, req.source));
        assert_eq!(PanoTaskStatus::try_from(2), Ok(PanoTaskStatus::Done));
    }
}
