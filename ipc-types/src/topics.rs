//! Service names and their quality of service.
//!
//! No process spells a topic by hand: it calls one of these functions. Every process
//! opens a topic with the same [`TopicQos`] (iceoryx2 refuses to open a service whose
//! requirements exceed what its creator set), so any of them may start first.

/// Capacity settings of a publish-subscribe topic and its wake-up event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TopicQos {
    pub max_publishers: usize,
    pub max_subscribers: usize,
    pub max_nodes: usize,
    /// Samples a late subscriber receives on connect (latest-value topics use 1).
    pub history: usize,
    /// Samples buffered per subscriber; the oldest is overwritten when full.
    pub buffer: usize,
}

impl TopicQos {
    /// A single-writer stream whose consumers want the newest value.
    pub const STATE: TopicQos = TopicQos {
        max_publishers: 2,
        max_subscribers: 32,
        max_nodes: 40,
        history: 1,
        buffer: 8,
    };
    /// Many writers (every gateway and engine), one executor; nothing should be lost.
    pub const COMMANDS: TopicQos = TopicQos {
        max_publishers: 24,
        max_subscribers: 4,
        max_nodes: 32,
        history: 0,
        buffer: 64,
    };
    /// One writer, many readers, each of which must see every answer.
    pub const EVENTS: TopicQos = TopicQos {
        max_publishers: 2,
        max_subscribers: 32,
        max_nodes: 40,
        history: 0,
        buffer: 64,
    };
    /// A latest-value topic that several sources may write (the geofence).
    pub const SHARED_STATE: TopicQos = TopicQos {
        max_publishers: 16,
        max_subscribers: 16,
        max_nodes: 32,
        history: 1,
        buffer: 4,
    };
    /// Large requests (kilobytes each) from one writer to one reader that must see
    /// each one: few subscribers and a short buffer, because shared memory is
    /// reserved for subscribers × buffer samples per publisher.
    pub const BULK_EVENTS: TopicQos = TopicQos {
        max_publishers: 2,
        max_subscribers: 4,
        max_nodes: 8,
        history: 0,
        buffer: 8,
    };
    /// A large latest-value sample (tens of kilobytes) from one writer to a few readers:
    /// the swarm state.
    pub const BULK_STATE: TopicQos = TopicQos {
        max_publishers: 2,
        max_subscribers: 8,
        max_nodes: 12,
        history: 1,
        buffer: 2,
    };
    /// Bursts of one small sample per drone between the GroundControl gateway and the
    /// swarm queue (a command for every drone of a 256-drone swarm in one client
    /// write; CHECK_ALL_IDLE's answer for every drone): the buffer holds several
    /// whole bursts, so a reader that wakes after the burst loses nothing. (With
    /// `COMMANDS`/`EVENTS`' 64, a 250-drone burst lost 186 samples.)
    pub const SWARM_BURST: TopicQos = TopicQos {
        max_publishers: 4,
        max_subscribers: 8,
        max_nodes: 12,
        history: 0,
        buffer: 1024,
    };
    /// Camera frames (megabytes each, iceoryx2 slice samples): one camera, a few
    /// consumers that want the newest frame. Shared memory is reserved per publisher
    /// for about subscribers × buffer + history + loans frames of the largest size,
    /// so every number here is small (≈ 12 × 6.2 MB for 1080p RGB).
    pub const FRAMES: TopicQos = TopicQos {
        max_publishers: 2,
        max_subscribers: 4,
        max_nodes: 8,
        history: 1,
        buffer: 2,
    };
    /// Per-service health and stats: one writer (two while a restart overlaps), the supervisor and tools read.
    pub const SERVICE: TopicQos = TopicQos {
        max_publishers: 2,
        max_subscribers: 4,
        max_nodes: 8,
        history: 1,
        buffer: 4,
    };

    /// Listeners of the topic's wake-up event: one per subscriber plus slack.
    pub const fn event_listeners(&self) -> usize {
        self.max_subscribers + 2
    }

    /// Notifiers of the topic's wake-up event: one per publisher plus one per
    /// subscriber (subscribers wake themselves on shutdown), plus slack.
    pub const fn event_notifiers(&self) -> usize {
        self.max_publishers + self.max_subscribers + 2
    }
}

/// A topic name with its QoS.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topic {
    pub name: String,
    pub qos: TopicQos,
}

impl Topic {
    fn new(name: String, qos: TopicQos) -> Self {
        Topic { name, qos }
    }
}

impl core::fmt::Display for Topic {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(&self.name)
    }
}

/// [`crate::VehicleState`] of vehicle `id`, at the autopilot's ATTITUDE rate.
pub fn vehicle_state(id: u8) -> Topic {
    Topic::new(format!("skymesh/vehicle/{id}/state"), TopicQos::STATE)
}

/// [`crate::VehicleStatus`] of vehicle `id`, on change and at 1 Hz.
pub fn vehicle_status(id: u8) -> Topic {
    Topic::new(format!("skymesh/vehicle/{id}/status"), TopicQos::STATE)
}

/// [`crate::VehicleCommand`]s for vehicle `id`, from every gateway and engine.
pub fn vehicle_command(id: u8) -> Topic {
    Topic::new(format!("skymesh/vehicle/{id}/command"), TopicQos::COMMANDS)
}

/// [`crate::CommandAck`]s from vehicle `id`'s autopilot link.
pub fn vehicle_command_ack(id: u8) -> Topic {
    Topic::new(
        format!("skymesh/vehicle/{id}/command_ack"),
        TopicQos::EVENTS,
    )
}

/// [`crate::AuthorityState`] of vehicle `id`: who holds flight and payload authority.
pub fn vehicle_authority(id: u8) -> Topic {
    Topic::new(format!("skymesh/vehicle/{id}/authority"), TopicQos::STATE)
}

/// [`crate::ArbiterEvent`]s of vehicle `id`'s arbiter.
pub fn vehicle_arbiter_events(id: u8) -> Topic {
    Topic::new(
        format!("skymesh/vehicle/{id}/arbiter_events"),
        TopicQos::EVENTS,
    )
}

/// [`crate::GeofenceSet`] for vehicle `id`, from whichever source sets the fence.
pub fn vehicle_geofence(id: u8) -> Topic {
    Topic::new(
        format!("skymesh/vehicle/{id}/geofence"),
        TopicQos::SHARED_STATE,
    )
}

/// [`crate::PayloadState`] of vehicle `id`: gimbal attitude and GoPro status.
pub fn vehicle_payload(id: u8) -> Topic {
    Topic::new(format!("skymesh/vehicle/{id}/payload"), TopicQos::STATE)
}

/// [`crate::ShotRequestSample`]s: what apps ask of the shot engine, translated by
/// their gateways (gateway → shot engine).
pub fn shot_requests() -> Topic {
    Topic::new("skymesh/shot/requests".into(), TopicQos::EVENTS)
}

/// [`crate::ShotEventSample`]s: what the shot engine tells the apps (shot engine →
/// gateways).
pub fn shot_events() -> Topic {
    Topic::new("skymesh/shot/events".into(), TopicQos::EVENTS)
}

/// [`crate::AppGeofence`]s: the Solo app's geofence polygons (gateway → shot engine).
/// 8 KiB a sample: [`TopicQos::BULK_EVENTS`] (with `EVENTS` each publisher would
/// reserve about 17 MB of shared memory).
pub fn shot_app_geofence() -> Topic {
    Topic::new("skymesh/shot/app_geofence".into(), TopicQos::BULK_EVENTS)
}

/// [`crate::AppSession`]: whether a Solo app is connected (gateway → shot engine).
pub fn shot_app_session() -> Topic {
    Topic::new("skymesh/shot/app_session".into(), TopicQos::STATE)
}

/// [`crate::ShotStatus`] of the shot engine.
pub fn shot_status() -> Topic {
    Topic::new("skymesh/shot/status".into(), TopicQos::STATE)
}

/// [`crate::ButtonEvent`]s from controller hardware (IMC gateway) and tools.
pub fn input_buttons() -> Topic {
    Topic::new("skymesh/input/buttons".into(), TopicQos::COMMANDS)
}

/// [`crate::TaskRequest`]s for vehicle `id` from gateways to the shot engine's
/// task runner.
pub fn task_request(id: u8) -> Topic {
    Topic::new(format!("skymesh/task/{id}/request"), TopicQos::COMMANDS)
}

/// [`crate::TaskEvent`]s of the task runner for vehicle `id`: replies and progress.
pub fn task_event(id: u8) -> Topic {
    Topic::new(format!("skymesh/task/{id}/event"), TopicQos::EVENTS)
}

/// [`crate::HardwareRequest`]s from gateways to the hardware service.
pub fn hardware_request() -> Topic {
    Topic::new("skymesh/hardware/request".into(), TopicQos::COMMANDS)
}

/// [`crate::HardwareReply`]s of the hardware service.
pub fn hardware_reply() -> Topic {
    Topic::new("skymesh/hardware/reply".into(), TopicQos::EVENTS)
}

/// [`crate::HardwareState`] of the hardware service (latest value).
pub fn hardware_state() -> Topic {
    Topic::new("skymesh/hardware/state".into(), TopicQos::STATE)
}

/// [`crate::SwarmCommand`]s from the GroundControl gateway to the swarm queue.
pub fn swarm_command() -> Topic {
    Topic::new("skymesh/swarm/command".into(), TopicQos::SWARM_BURST)
}

/// [`crate::SwarmReply`]s of the swarm queue.
pub fn swarm_reply() -> Topic {
    Topic::new("skymesh/swarm/reply".into(), TopicQos::SWARM_BURST)
}

/// [`crate::SwarmState`]: every drone of the swarm queue (about 20 KiB, latest value).
pub fn swarm_state() -> Topic {
    Topic::new("skymesh/swarm/state".into(), TopicQos::BULK_STATE)
}

/// [`crate::SwarmWatch`]: the pose broadcast's word that it reads the swarm state
/// at the queue's rate (latest value per publisher).
pub fn swarm_watch() -> Topic {
    Topic::new("skymesh/swarm/watch".into(), TopicQos::SHARED_STATE)
}

/// Frames of camera stream `stream` ([`crate::FrameHeader`] + pixels), published by
/// the camera service in place in shared memory.
pub fn camera_frames(stream: &str) -> Topic {
    Topic::new(format!("skymesh/camera/{stream}/frames"), TopicQos::FRAMES)
}

/// [`crate::CameraDemand`] of camera stream `stream`: its readers' word that they read
/// its frames now (latest value per publisher).
pub fn camera_demand(stream: &str) -> Topic {
    Topic::new(
        format!("skymesh/camera/{stream}/demand"),
        TopicQos::SHARED_STATE,
    )
}

/// [`crate::SceneTruth`] of camera stream `stream`'s synthetic scene: the true target
/// positions, one per rendered frame.
pub fn camera_truth(stream: &str) -> Topic {
    Topic::new(format!("skymesh/camera/{stream}/truth"), TopicQos::STATE)
}

/// [`crate::VisionState`]: the vision pipeline's parameters, virtual cameras,
/// tracker and detections (tens of kilobytes, latest value).
pub fn vision_state() -> Topic {
    Topic::new("skymesh/vision/state".into(), TopicQos::BULK_STATE)
}

/// [`crate::VisionControl`] requests to the vision pipeline (DigiView gateway,
/// autopilot-link's gimbal protocol v2 and forwarded camera commands).
pub fn vision_control() -> Topic {
    Topic::new("skymesh/vision/control".into(), TopicQos::COMMANDS)
}

/// [`crate::VisionReply`]: one per [`crate::VisionControl`], to every requester (each
/// matches its own `request_id`).
pub fn vision_reply() -> Topic {
    Topic::new("skymesh/vision/reply".into(), TopicQos::EVENTS)
}

/// [`crate::VisionDemand`]: consumers' word that they use the vision pipeline's
/// output now (latest value per publisher).
pub fn vision_demand() -> Topic {
    Topic::new("skymesh/vision/demand".into(), TopicQos::SHARED_STATE)
}

/// The vision pipeline's rendered output of stream `stream` (virtual camera views and
/// detection overlay), [`crate::FrameHeader`] + RGB24 pixels like the camera's frames.
pub fn vision_output(stream: &str) -> Topic {
    Topic::new(format!("skymesh/vision/{stream}/output"), TopicQos::FRAMES)
}

/// [`crate::ServiceHealth`] heartbeats of the service instance `name`.
pub fn service_health(name: &str) -> Topic {
    Topic::new(format!("skymesh/service/{name}/health"), TopicQos::SERVICE)
}

/// [`crate::ServiceStats`] of the service instance `name`.
pub fn service_stats(name: &str) -> Topic {
    Topic::new(format!("skymesh/service/{name}/stats"), TopicQos::SERVICE)
}

/// True if `name` can be a service instance name (it becomes part of topic and file names).
pub fn is_valid_instance_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= 32
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_carry_the_vehicle_id() {
        assert_eq!(vehicle_state(3).name, "skymesh/vehicle/3/state");
        assert_eq!(vehicle_command(255).name, "skymesh/vehicle/255/command");
        assert_eq!(
            service_health("vehicle-sim-2").name,
            "skymesh/service/vehicle-sim-2/health"
        );
    }

    #[test]
    fn instance_names_are_checked() {
        assert!(is_valid_instance_name("autopilot-link"));
        assert!(!is_valid_instance_name("a/b"));
        assert!(!is_valid_instance_name(""));
        assert!(!is_valid_instance_name(&"x".repeat(33)));
    }
}
