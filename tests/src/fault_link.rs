//! A MAVLink link that loses frames on purpose: a TCP proxy between autopilot-link
//! and vehicle-sim ([`crate::MeshOptions::link_via`]) that forwards whole frames,
//! both ways, unless a test's rule drops them, and keeps a log of what
//! autopilot-link sent and what vehicle-sim acknowledged (with the instant each was
//! read), so a test can say what went out and when.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use anyhow::Result;
use mavlink::dialects::ardupilotmega::MavMessage;
use mavlink_frame::FrameParser;

use crate::{Mesh, MeshOptions};

/// Which way a frame travels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dir {
    /// autopilot-link → vehicle-sim.
    ToVehicle,
    /// vehicle-sim → autopilot-link.
    ToLink,
}

/// One frame the proxy saw (every frame to the vehicle; COMMAND_ACK from it).
#[derive(Debug, Clone)]
pub struct Seen {
    pub at: Instant,
    pub dir: Dir,
    pub msg: MavMessage,
    pub dropped: bool,
}

type Rule = Box<dyn FnMut(Dir, &MavMessage) -> bool + Send>;

/// The proxy's shared state: the drop rule and the log.
#[derive(Clone)]
pub struct FaultLink {
    rule: Arc<Mutex<Rule>>,
    log: Arc<Mutex<Vec<Seen>>>,
}

impl std::fmt::Debug for FaultLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FaultLink")
            .field("seen", &self.lock_log().len())
            .finish()
    }
}

impl FaultLink {
    /// Sets the rule: `true` drops the frame. Replaces the previous rule.
    pub fn set_rule(&self, rule: impl FnMut(Dir, &MavMessage) -> bool + Send + 'static) {
        *self.rule.lock().unwrap_or_else(|p| p.into_inner()) = Box::new(rule);
    }

    /// Forwards everything from now on.
    pub fn clear_rule(&self) {
        self.set_rule(|_, _| false);
    }

    /// What was logged so far matching `pick`.
    pub fn seen(&self, mut pick: impl FnMut(&Seen) -> bool) -> Vec<Seen> {
        self.lock_log()
            .iter()
            .filter(|s| pick(s))
            .cloned()
            .collect()
    }

    fn lock_log(&self) -> MutexGuard<'_, Vec<Seen>> {
        self.log.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn pass(&self, dir: Dir, msg: &MavMessage, at: Instant) -> bool {
        let dropped = (self.rule.lock().unwrap_or_else(|p| p.into_inner()))(dir, msg);
        if dir == Dir::ToVehicle || matches!(msg, MavMessage::COMMAND_ACK(_)) {
            self.lock_log().push(Seen {
                at,
                dir,
                msg: msg.clone(),
                dropped,
            });
        }
        !dropped
    }
}

/// Starts a mesh (`opts`) whose vehicle 1 autopilot-link reaches its vehicle-sim
/// through a [`FaultLink`] (forwarding everything until a rule is set), and waits
/// until `services` run.
pub fn start_faulty_mesh(opts: MeshOptions, services: &[&str]) -> Result<(Mesh, FaultLink)> {
    let listener = TcpListener::bind("127.0.0.1:0")?;
    let opts = MeshOptions {
        link_via: Some(listener.local_addr()?.port()),
        ..opts
    };
    let mut mesh = Mesh::start(opts)?;
    let link = FaultLink {
        rule: Arc::new(Mutex::new(Box::new(|_, _| false))),
        log: Arc::default(),
    };
    let sim_port = mesh.mavlink_port;
    let proxy = link.clone();
    std::thread::spawn(move || loop {
        let Ok((to_link, _)) = listener.accept() else {
            return;
        };
        let Ok(to_sim) = TcpStream::connect(("127.0.0.1", sim_port)) else {
            continue;
        };
        let _ = to_link.set_nodelay(true);
        let _ = to_sim.set_nodelay(true);
        let (Ok(from_link), Ok(from_sim)) = (to_link.try_clone(), to_sim.try_clone()) else {
            continue;
        };
        let p = proxy.clone();
        std::thread::spawn(move || forward(from_sim, to_link, Dir::ToLink, &p));
        let p = proxy.clone();
        std::thread::spawn(move || forward(from_link, to_sim, Dir::ToVehicle, &p));
    });
    for name in services {
        mesh.wait_running(name, Duration::from_secs(40))?;
    }
    Ok((mesh, link))
}

/// Copies whole frames from `from` to `to` while the rule lets them pass.
fn forward(mut from: TcpStream, mut to: TcpStream, dir: Dir, link: &FaultLink) {
    let mut parser = FrameParser::new();
    let mut buf = [0u8; 4096];
    while let Ok(n) = from.read(&mut buf) {
        if n == 0 {
            break;
        }
        let at = Instant::now();
        parser.push(&buf[..n]);
        while let Some(frame) = parser.next_frame() {
            // A frame this dialect cannot decode is forwarded untouched.
            let pass = frame.decode().map_or(true, |msg| link.pass(dir, &msg, at));
            if pass && to.write_all(frame.as_bytes()).is_err() {
                return;
            }
        }
    }
    let _ = to.shutdown(std::net::Shutdown::Both);
}
