//! Which bus topics `skymesh record` and `skymesh replay` support: topic names and
//! glob patterns, the sample type each topic carries, and the topics that exist on
//! the bus now (iceoryx2's service listing).

use iceoryx2::service::static_config::messaging_pattern::MessagingPattern;
use iceoryx2::service::Service as _;
use skymesh_ipc_types::{topics, Topic};
use skymesh_runtime::ipc::Svc;
use skymesh_runtime::Domain;

/// A sample type that can be recorded: one per supported topic family.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Kind {
    VehicleState,
    VehicleStatus,
    VehicleCommand,
    CommandAck,
    AuthorityState,
    ArbiterEvent,
    GeofenceSet,
    PayloadState,
    VisionState,
    SwarmState,
}

/// One supported topic family.
#[derive(Debug, Clone, Copy)]
pub struct Family {
    pub kind: Kind,
    /// The topic name, `{id}` standing for a vehicle id (0..=255).
    pub template: &'static str,
    /// The sample's iceoryx2 type name (with its layout version): the MCAP schema name.
    pub schema_name: &'static str,
}

/// Every supported family. Camera and vision frames (megabytes of pixels), task
/// and shot-API samples, the service topics and the request/reply topics of the
/// hardware, vision and swarm services are not recorded.
pub const FAMILIES: [Family; 10] = [
    Family {
        kind: Kind::VehicleState,
        template: "skymesh/vehicle/{id}/state",
        schema_name: "skymesh.VehicleState.v2",
    },
    Family {
        kind: Kind::VehicleStatus,
        template: "skymesh/vehicle/{id}/status",
        schema_name: "skymesh.VehicleStatus.v1",
    },
    Family {
        kind: Kind::VehicleCommand,
        template: "skymesh/vehicle/{id}/command",
        schema_name: "skymesh.VehicleCommand.v2",
    },
    Family {
        kind: Kind::CommandAck,
        template: "skymesh/vehicle/{id}/command_ack",
        schema_name: "skymesh.CommandAck.v2",
    },
    Family {
        kind: Kind::AuthorityState,
        template: "skymesh/vehicle/{id}/authority",
        schema_name: "skymesh.AuthorityState.v2",
    },
    Family {
        kind: Kind::ArbiterEvent,
        template: "skymesh/vehicle/{id}/arbiter_events",
        schema_name: "skymesh.ArbiterEvent.v2",
    },
    Family {
        kind: Kind::GeofenceSet,
        template: "skymesh/vehicle/{id}/geofence",
        schema_name: "skymesh.GeofenceSet.v2",
    },
    Family {
        kind: Kind::PayloadState,
        template: "skymesh/vehicle/{id}/payload",
        schema_name: "skymesh.PayloadState.v1",
    },
    Family {
        kind: Kind::VisionState,
        template: "skymesh/vision/state",
        schema_name: "skymesh.VisionState.v1",
    },
    Family {
        kind: Kind::SwarmState,
        template: "skymesh/swarm/state",
        schema_name: "skymesh.SwarmState.v1",
    },
];

impl Kind {
    pub fn family(self) -> &'static Family {
        // FAMILIES lists every kind once.
        FAMILIES
            .iter()
            .find(|f| f.kind == self)
            .unwrap_or(&FAMILIES[0])
    }

    pub fn schema_name(self) -> &'static str {
        self.family().schema_name
    }

    /// The kind whose MCAP schema is `name`.
    pub fn from_schema_name(name: &str) -> Option<Kind> {
        FAMILIES
            .iter()
            .find(|f| f.schema_name == name)
            .map(|f| f.kind)
    }
}

/// The supported topic templates, one per line, for error messages and `--help`.
pub fn supported_list() -> String {
    FAMILIES
        .iter()
        .map(|f| format!("  {}  ({})", f.template, f.schema_name))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The sample type and QoS of the topic `name`, if it is a supported one.
pub fn parse(name: &str) -> Option<(Kind, Topic)> {
    if let Some(rest) = name.strip_prefix("skymesh/vehicle/") {
        let (id, suffix) = rest.split_once('/')?;
        let id: u8 = id.parse().ok()?;
        // One spelling per topic: "01" or "+1" would name another service.
        if id.to_string() != rest[..rest.len() - suffix.len() - 1] {
            return None;
        }
        let (kind, topic) = match suffix {
            "state" => (Kind::VehicleState, topics::vehicle_state(id)),
            "status" => (Kind::VehicleStatus, topics::vehicle_status(id)),
            "command" => (Kind::VehicleCommand, topics::vehicle_command(id)),
            "command_ack" => (Kind::CommandAck, topics::vehicle_command_ack(id)),
            "authority" => (Kind::AuthorityState, topics::vehicle_authority(id)),
            "arbiter_events" => (Kind::ArbiterEvent, topics::vehicle_arbiter_events(id)),
            "geofence" => (Kind::GeofenceSet, topics::vehicle_geofence(id)),
            "payload" => (Kind::PayloadState, topics::vehicle_payload(id)),
            _ => return None,
        };
        return Some((kind, topic));
    }
    let vision = topics::vision_state();
    if name == vision.name {
        return Some((Kind::VisionState, vision));
    }
    let swarm = topics::swarm_state();
    if name == swarm.name {
        return Some((Kind::SwarmState, swarm));
    }
    None
}

/// True if `pattern` has glob characters (`*`, `?`).
pub fn is_glob(pattern: &str) -> bool {
    pattern.contains(['*', '?'])
}

/// Glob match of a topic name: `*` matches any run of characters except `/`, `**`
/// any run including `/`, `?` one character other than `/`.
pub fn glob_match(pattern: &str, name: &str) -> bool {
    fn go(p: &[u8], n: &[u8]) -> bool {
        match p.first() {
            None => n.is_empty(),
            Some(b'*') if p.get(1) == Some(&b'*') => (0..=n.len()).any(|i| go(&p[2..], &n[i..])),
            Some(b'*') => {
                let seg = n.iter().position(|&c| c == b'/').unwrap_or(n.len());
                (0..=seg).any(|i| go(&p[1..], &n[i..]))
            }
            Some(b'?') => n.first().is_some_and(|&c| c != b'/') && go(&p[1..], &n[1..]),
            Some(&c) => n.first() == Some(&c) && go(&p[1..], &n[1..]),
        }
    }
    go(pattern.as_bytes(), name.as_bytes())
}

/// The names of the publish-subscribe topics that exist in `domain` now, sorted.
pub fn list_bus_topics(domain: &Domain) -> anyhow::Result<Vec<String>> {
    let mut names = Vec::new();
    Svc::list(&domain.config, |details| {
        if matches!(
            details.static_details.messaging_pattern(),
            MessagingPattern::PublishSubscribe(_)
        ) {
            names.push(details.static_details.name().as_str().to_string());
        }
        iceoryx2::prelude::CallbackProgression::Continue
    })
    .map_err(|e| anyhow::anyhow!("listing the topics of domain {}: {e:?}", domain.name))?;
    names.sort();
    names.dedup();
    Ok(names)
}

/// What the patterns on the command line ask for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Selection {
    /// Topics named exactly (recorded whether or not they exist yet).
    pub names: Vec<String>,
    /// Glob patterns, resolved against the bus's topics now and as topics appear.
    pub globs: Vec<String>,
}

/// Sorts the command line's topics into exact names and globs; an exact name of
/// an unsupported topic is refused with the list of supported ones.
pub fn select(patterns: &[String]) -> anyhow::Result<Selection> {
    if patterns.is_empty() {
        anyhow::bail!(
            "name at least one topic or glob; supported topics:\n{}",
            supported_list()
        );
    }
    let mut sel = Selection {
        names: Vec::new(),
        globs: Vec::new(),
    };
    for p in patterns {
        if is_glob(p) {
            sel.globs.push(p.clone());
        } else if parse(p).is_some() {
            sel.names.push(p.clone());
        } else {
            anyhow::bail!(
                "topic {p:?} cannot be recorded (its sample type has no JSON encoding); supported topics:\n{}",
                supported_list()
            );
        }
    }
    Ok(sel)
}

impl Selection {
    /// The topics of `existing` a glob matches, split into supported and not.
    pub fn matches<'a>(&self, existing: &'a [String]) -> (Vec<&'a str>, Vec<&'a str>) {
        let mut supported = Vec::new();
        let mut refused = Vec::new();
        for name in existing {
            if self.globs.iter().any(|g| glob_match(g, name)) {
                if parse(name).is_some() {
                    supported.push(name.as_str());
                } else {
                    refused.push(name.as_str());
                }
            }
        }
        (supported, refused)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vehicle_topics_parse_with_their_qos() {
        let (kind, topic) = parse("skymesh/vehicle/7/state").unwrap();
        assert_eq!(kind, Kind::VehicleState);
        assert_eq!(topic, topics::vehicle_state(7));
        let (kind, topic) = parse("skymesh/vehicle/255/command").unwrap();
        assert_eq!(kind, Kind::VehicleCommand);
        assert_eq!(topic.qos, topics::vehicle_command(255).qos);
        assert_eq!(parse("skymesh/swarm/state").unwrap().0, Kind::SwarmState);
        assert_eq!(parse("skymesh/vision/state").unwrap().0, Kind::VisionState);
        for bad in [
            "skymesh/vehicle/256/state",
            "skymesh/vehicle/01/state",
            "skymesh/vehicle/+1/state",
            "skymesh/vehicle/1/unknown",
            "skymesh/camera/main/frames",
            "skymesh/task/1/request",
            "skymesh/shot/requests",
        ] {
            assert!(parse(bad).is_none(), "{bad}");
        }
    }

    #[test]
    fn every_family_template_parses_to_its_kind() {
        for f in &FAMILIES {
            let name = f.template.replace("{id}", "3");
            assert_eq!(parse(&name).map(|p| p.0), Some(f.kind), "{name}");
            assert_eq!(Kind::from_schema_name(f.schema_name), Some(f.kind));
        }
    }

    #[test]
    fn globs_match_within_segments() {
        assert!(glob_match(
            "skymesh/vehicle/*/state",
            "skymesh/vehicle/1/state"
        ));
        assert!(!glob_match(
            "skymesh/vehicle/*/state",
            "skymesh/vehicle/1/status"
        ));
        assert!(!glob_match("skymesh/*/state", "skymesh/vehicle/1/state"));
        assert!(glob_match("skymesh/**/state", "skymesh/vehicle/1/state"));
        assert!(glob_match(
            "skymesh/vehicle/?/*",
            "skymesh/vehicle/1/command_ack"
        ));
        assert!(!glob_match(
            "skymesh/vehicle/?/*",
            "skymesh/vehicle/12/state"
        ));
        assert!(glob_match(
            "skymesh/vehicle/1/*",
            "skymesh/vehicle/1/arbiter_events"
        ));
    }

    #[test]
    fn unsupported_names_are_refused_naming_the_supported_ones() {
        let err = select(&["skymesh/camera/main/frames".into()])
            .unwrap_err()
            .to_string();
        assert!(err.contains("cannot be recorded"), "{err}");
        assert!(err.contains("skymesh/vehicle/{id}/state"), "{err}");
        let sel = select(&[
            "skymesh/vehicle/*/state".into(),
            "skymesh/swarm/state".into(),
        ])
        .unwrap();
        assert_eq!(sel.globs, ["skymesh/vehicle/*/state"]);
        assert_eq!(sel.names, ["skymesh/swarm/state"]);
        let existing: Vec<String> = [
            "skymesh/vehicle/1/state",
            "skymesh/vehicle/1/status",
            "skymesh/task/1/request",
        ]
        .map(String::from)
        .to_vec();
        let all = select(&["skymesh/*/*/*".into()]).unwrap();
        let (ok, refused) = all.matches(&existing);
        assert_eq!(ok, ["skymesh/vehicle/1/state", "skymesh/vehicle/1/status"]);
        assert_eq!(refused, ["skymesh/task/1/request"]);
    }
}
