//! The core on the sim backend in a temp dir, time stepped by hand.

use std::path::Path;
use std::time::Duration;

use skymesh_ipc_types::hardware::{LcdOp, PowerChannelOp, SystemPowerOp};
use skymesh_ipc_types::{
    FixedStr, HardwareOp, HardwareReply, HardwareRequest, HardwareResult, HwName, SampleHeader,
};
use skymesh_runtime::Stats;

use super::*;
use crate::config::RawConfig;

const DEVICES: &str = r#"
restart_delay_s = 1.0
[[led]]
name = "status"
[[led]]
name = "red"
[[gpio]]
name = "payload_release"
direction = "output"
[[gpio]]
name = "button_a"
direction = "input"
[[power_channel]]
name = "camera"
default = "on"
[[power_channel]]
name = "lights"
default = "off"
[lcd]
backend = "sim"
width = 16
"#;

const WITH_COMMANDS: &str = r#"
[power]
power_down_command = ["/sbin/poweroff", "--now"]
power_up_command = ["/usr/local/bin/wake-peripherals"]
power_down_delay_s = 10
"#;

fn settings(dir: &Path, extra: &str) -> Settings {
    let text = format!("state_dir = \"{}\"\n{DEVICES}{extra}", dir.display());
    let raw: RawConfig = toml::from_str(&text).expect("toml");
    raw.validate_with_env(None, None).expect("valid")
}

struct Rig {
    dir: tempfile::TempDir,
    hw: Hardware,
    stats: Stats,
    t0: Now,
    next_id: u32,
}

impl Rig {
    fn new(extra: &str) -> Rig {
        let dir = tempfile::tempdir().unwrap();
        let stats = Stats::new();
        let hw = Hardware::start(&settings(dir.path(), extra), Metrics::new(&stats)).unwrap();
        Rig {
            dir,
            hw,
            stats,
            t0: Now {
                mono: Duration::from_secs(1000),
                unix_s: 1_700_000_000.0,
            },
            next_id: 0,
        }
    }

    /// Stops the core and starts a new one on the same state directory.
    fn restart(self, extra: &str) -> Rig {
        let Rig { dir, hw, .. } = self;
        drop(hw);
        let stats = Stats::new();
        let hw = Hardware::start(&settings(dir.path(), extra), Metrics::new(&stats)).unwrap();
        Rig {
            dir,
            hw,
            stats,
            t0: Now {
                mono: Duration::from_secs(5000),
                unix_s: 1_700_010_000.0,
            },
            next_id: 0,
        }
    }

    fn at(&self, s: f64) -> Now {
        self.t0.after(Duration::from_secs_f64(s))
    }

    fn file(&self, rel: &str) -> String {
        std::fs::read_to_string(self.dir.path().join(rel))
            .unwrap()
            .trim_end()
            .to_string()
    }

    fn write(&self, rel: &str, content: &str) {
        std::fs::write(self.dir.path().join(rel), content).unwrap();
    }

    fn send(&mut self, mut req: HardwareRequest, at: f64) -> Answer {
        self.next_id += 1;
        req.request_id = self.next_id;
        req.header = SampleHeader {
            service: 12,
            instance: 3,
            ..SampleHeader::default()
        };
        let now = self.at(at);
        let a = self.hw.handle(&req, now);
        assert_eq!(a.reply.request_id, self.next_id);
        assert_eq!(
            (a.reply.requester_service, a.reply.requester_instance),
            (12, 3)
        );
        assert_eq!(a.reply.op, req.op);
        assert_eq!(a.reply.name, req.name);
        assert!(a.reply.answers(&req.header, self.next_id));
        a
    }

    fn metric(&self, name: &str, labels: &str) -> Option<f64> {
        self.stats.value(name, labels)
    }
}

fn req(op: HardwareOp, name: &str) -> HardwareRequest {
    HardwareRequest {
        name: HwName::new(name),
        ..HardwareRequest::new(0, op)
    }
}

fn with_value(mut r: HardwareRequest, value: u8) -> HardwareRequest {
    r.value = value;
    r
}

fn channel(name: &str, op: PowerChannelOp, sched_s: f64) -> HardwareRequest {
    HardwareRequest {
        sub_op: op.to_wire(),
        sched_s,
        ..req(HardwareOp::PowerChannel, name)
    }
}

fn lcd(op: LcdOp, text: &str) -> HardwareRequest {
    HardwareRequest {
        sub_op: op.to_wire(),
        text: FixedStr::new(text),
        ..HardwareRequest::new(0, HardwareOp::Lcd)
    }
}

fn system(op: SystemPowerOp, sched_s: f64) -> HardwareRequest {
    HardwareRequest {
        sub_op: op.to_wire(),
        sched_s,
        ..HardwareRequest::new(0, HardwareOp::SystemPower)
    }
}

fn result(r: &HardwareReply) -> HardwareResult {
    r.result().expect("known result")
}

#[test]
fn start_opens_every_device_in_its_initial_state() {
    let rig = Rig::new("");
    let s = rig.hw.state(rig.t0);
    assert_eq!((s.n_leds, s.n_gpios, s.n_channels), (2, 2, 2));
    assert_eq!(s.led("status").map(|l| l.value), Some(0));
    assert_eq!(
        s.gpio("payload_release").map(|g| (g.value, g.output)),
        Some((0, 1))
    );
    assert_eq!(
        s.gpio("button_a").map(|g| (g.value, g.output)),
        Some((0, 0))
    );
    let cam = s.channel("camera").unwrap();
    assert_eq!((cam.on, cam.saved), (1, 0));
    assert!(cam.sched_on_in_s < 0.0 && cam.sched_off_in_s < 0.0);
    assert_eq!(s.channel("lights").map(|c| c.on), Some(0));
    assert_eq!(s.lcd_on, 1);
    assert_eq!(s.system_power, SystemPowerOp::PowerDownAborted.to_wire());
    assert!(s.system_power_in_s < 0.0);
    assert_eq!(rig.file("led/status"), "0");
    assert_eq!(rig.file("power/camera"), "1");
    assert_eq!(rig.file("power/lights"), "0");
    assert_eq!(rig.file("lcd_on"), "1");
    assert_eq!(
        rig.metric("skymesh_hardware_power_channel_on", "channel=camera"),
        Some(1.0)
    );
    assert_eq!(rig.hw.next_due(rig.t0), None);
}

#[test]
fn leds_are_set_and_queried_from_the_device() {
    let mut rig = Rig::new("");
    let a = rig.send(with_value(req(HardwareOp::LedSet, "status"), 200), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::Ok);
    assert_eq!(a.reply.value, 200);
    assert!(a.reply.message.is_empty());
    assert!(a.changed);
    assert_eq!(rig.file("led/status"), "200");
    assert_eq!(
        rig.hw.state(rig.t0).led("status").map(|l| l.value),
        Some(200)
    );
    // The same value again: answered, nothing changed.
    let a = rig.send(with_value(req(HardwareOp::LedSet, "status"), 200), 0.0);
    assert!(!a.changed);
    // Someone else changed the device: a query reads it.
    rig.write("led/status", "17\n");
    let a = rig.send(req(HardwareOp::LedQuery, "status"), 0.0);
    assert_eq!((result(&a.reply), a.reply.value), (HardwareResult::Ok, 17));
    assert!(a.changed);
    let a = rig.send(req(HardwareOp::LedQuery, "purple"), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::UnknownName);
    assert!(a.reply.message.as_str().contains("purple"));
    let a = rig.send(req(HardwareOp::LedQuery, ""), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::UnknownName);
    assert_eq!(
        rig.metric("skymesh_hardware_requests_total", "op=led_set,result=ok"),
        Some(2.0)
    );
    assert_eq!(
        rig.metric(
            "skymesh_hardware_requests_total",
            "op=led_query,result=unknown_name"
        ),
        Some(2.0)
    );
}

#[test]
fn a_failing_device_is_a_backend_error_and_keeps_the_known_state() {
    let mut rig = Rig::new("");
    rig.send(with_value(req(HardwareOp::LedSet, "red"), 9), 0.0);
    let path = rig.dir.path().join("led/red");
    std::fs::remove_file(&path).unwrap();
    std::fs::create_dir_all(path.join("blocker")).unwrap();
    let a = rig.send(with_value(req(HardwareOp::LedSet, "red"), 50), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::BackendError);
    assert_eq!(a.reply.value, 9);
    assert!(
        a.reply.message.as_str().contains("led/red"),
        "{}",
        a.reply.message
    );
    assert!(!a.changed);
    assert_eq!(rig.hw.state(rig.t0).led("red").map(|l| l.value), Some(9));
    assert_eq!(
        rig.metric("skymesh_hardware_backend_errors_total", "device=led"),
        Some(1.0)
    );
}

#[test]
fn gpio_outputs_are_driven_and_inputs_read() {
    let mut rig = Rig::new("");
    let a = rig.send(
        with_value(req(HardwareOp::GpioSet, "payload_release"), 1),
        0.0,
    );
    assert_eq!((result(&a.reply), a.reply.value), (HardwareResult::Ok, 1));
    assert!(a.changed);
    assert_eq!(rig.file("gpio/payload_release"), "1");
    let a = rig.send(req(HardwareOp::GpioGet, "payload_release"), 0.0);
    assert_eq!(a.reply.value, 1);
    let a = rig.send(
        with_value(req(HardwareOp::GpioSet, "payload_release"), 2),
        0.0,
    );
    assert_eq!(result(&a.reply), HardwareResult::InvalidValue);
    assert_eq!(a.reply.value, 1, "the level stays");
    let a = rig.send(with_value(req(HardwareOp::GpioSet, "button_a"), 1), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::NotSupported);
    assert_eq!(rig.file("gpio/button_a"), "0");
    // The button is pressed: GpioGet reads the device, and so does the 1 Hz poll.
    rig.write("gpio/button_a", "1\n");
    let a = rig.send(req(HardwareOp::GpioGet, "button_a"), 0.0);
    assert_eq!((result(&a.reply), a.reply.value), (HardwareResult::Ok, 1));
    assert!(a.changed);
    rig.write("gpio/button_a", "0\n");
    assert!(rig.hw.poll_inputs());
    assert!(!rig.hw.poll_inputs());
    assert_eq!(
        rig.hw.state(rig.t0).gpio("button_a").map(|g| g.value),
        Some(0)
    );
    let a = rig.send(req(HardwareOp::GpioGet, "nope"), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::UnknownName);
}

#[test]
fn power_channels_switch_on_off_and_toggle() {
    let mut rig = Rig::new("");
    let a = rig.send(channel("lights", PowerChannelOp::TurnOn, 0.0), 0.0);
    assert_eq!((result(&a.reply), a.reply.value), (HardwareResult::Ok, 1));
    assert_eq!(a.reply.sub_op, PowerChannelOp::TurnOn.to_wire());
    assert!(a.reply.time_remaining_s < 0.0);
    assert_eq!(rig.file("power/lights"), "1");
    assert_eq!(
        rig.metric("skymesh_hardware_power_channel_on", "channel=lights"),
        Some(1.0)
    );
    let a = rig.send(channel("lights", PowerChannelOp::Toggle, 0.0), 0.0);
    assert_eq!(a.reply.value, 0);
    assert_eq!(rig.file("power/lights"), "0");
    let a = rig.send(channel("camera", PowerChannelOp::TurnOff, 0.0), 0.0);
    assert_eq!(a.reply.value, 0);
    assert_eq!(
        rig.hw.state(rig.t0).channel("camera").map(|c| c.on),
        Some(0)
    );
    let a = rig.send(channel("radio", PowerChannelOp::TurnOn, 0.0), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::UnknownName);
}

#[test]
fn scheduled_on_and_off_run_on_the_given_clock() {
    let mut rig = Rig::new("");
    let a = rig.send(channel("lights", PowerChannelOp::ScheduleOn, 5.0), 0.0);
    assert_eq!((result(&a.reply), a.reply.value), (HardwareResult::Ok, 0));
    assert_eq!(a.reply.time_remaining_s, 5.0);
    assert!(a.changed);
    let s = rig.hw.state(rig.at(2.0));
    let l = s.channel("lights").unwrap();
    assert_eq!((l.on, l.sched_on_in_s, l.sched_off_in_s), (0, 3.0, -1.0));
    assert_eq!(rig.hw.next_due(rig.at(2.0)), Some(Duration::from_secs(3)));
    let t = rig.hw.tick(rig.at(4.9));
    assert!(!t.changed);
    assert_eq!(rig.file("power/lights"), "0");
    let t = rig.hw.tick(rig.at(5.0));
    assert!(t.changed && t.effects.is_empty());
    assert_eq!(rig.file("power/lights"), "1");
    let l = *rig.hw.state(rig.at(5.0)).channel("lights").unwrap();
    assert_eq!((l.on, l.sched_on_in_s), (1, -1.0));
    assert_eq!(rig.hw.next_due(rig.at(5.0)), None);

    // A newer schedule of the same kind replaces the older one.
    rig.send(channel("lights", PowerChannelOp::ScheduleOff, 10.0), 6.0);
    let a = rig.send(channel("lights", PowerChannelOp::ScheduleOff, 3.0), 6.0);
    assert_eq!(a.reply.time_remaining_s, 3.0);
    assert_eq!(rig.hw.next_due(rig.at(6.0)), Some(Duration::from_secs(3)));
    assert!(!rig.hw.tick(rig.at(8.0)).changed);
    assert!(rig.hw.tick(rig.at(9.0)).changed);
    assert_eq!(rig.file("power/lights"), "0");
    assert!(
        !rig.hw.tick(rig.at(16.0)).changed,
        "the replaced one is gone"
    );

    // A request arriving after the due time sees the schedule applied first.
    rig.send(channel("camera", PowerChannelOp::ScheduleOff, 1.0), 20.0);
    let a = rig.send(channel("camera", PowerChannelOp::Toggle, 0.0), 30.0);
    assert_eq!(a.reply.value, 1, "off at 21 s, then toggled on");
    assert!(a.changed);

    // Zero seconds: done before the reply.
    let a = rig.send(channel("lights", PowerChannelOp::ScheduleOn, 0.0), 40.0);
    assert_eq!((a.reply.value, a.reply.time_remaining_s), (1, 0.0));
}

#[test]
fn a_bad_schedule_is_invalid() {
    let mut rig = Rig::new("");
    for s in [-1.0, f64::NAN, f64::INFINITY, 8.0 * 86_400.0] {
        let a = rig.send(channel("lights", PowerChannelOp::ScheduleOn, s), 0.0);
        assert_eq!(result(&a.reply), HardwareResult::InvalidValue, "{s}");
        assert!(a.reply.message.as_str().contains("sched_s"));
    }
    assert_eq!(rig.hw.next_due(rig.t0), None);
}

#[test]
fn schedule_reset_cancels_both() {
    let mut rig = Rig::new("");
    rig.send(channel("lights", PowerChannelOp::ScheduleOn, 5.0), 0.0);
    let a = rig.send(channel("lights", PowerChannelOp::ScheduleOff, 8.0), 0.0);
    assert_eq!(a.reply.time_remaining_s, 8.0);
    let a = rig.send(channel("lights", PowerChannelOp::TurnOn, 0.0), 1.0);
    assert_eq!(
        a.reply.time_remaining_s, 4.0,
        "on/off leave schedules alone"
    );
    let a = rig.send(channel("lights", PowerChannelOp::ScheduleReset, 0.0), 1.0);
    assert_eq!(result(&a.reply), HardwareResult::Ok);
    assert!(a.changed && a.reply.time_remaining_s < 0.0);
    let l = *rig.hw.state(rig.at(1.0)).channel("lights").unwrap();
    assert!(l.sched_on_in_s < 0.0 && l.sched_off_in_s < 0.0);
    assert_eq!(rig.hw.next_due(rig.at(1.0)), None);
    assert!(!rig.hw.tick(rig.at(100.0)).changed);
    assert_eq!(rig.file("power/lights"), "1");
    let a = rig.send(channel("lights", PowerChannelOp::ScheduleReset, 0.0), 2.0);
    assert!(!a.changed);
    assert!(a.reply.message.as_str().contains("nothing"));
}

#[test]
fn restart_is_off_then_on_after_the_delay() {
    let mut rig = Rig::new("");
    let a = rig.send(channel("camera", PowerChannelOp::Restart, 0.0), 0.0);
    assert_eq!((result(&a.reply), a.reply.value), (HardwareResult::Ok, 0));
    assert_eq!(a.reply.time_remaining_s, 1.0);
    assert_eq!(a.reply.sub_op, PowerChannelOp::Restart.to_wire());
    assert_eq!(rig.file("power/camera"), "0");
    assert_eq!(
        rig.hw
            .state(rig.t0)
            .channel("camera")
            .map(|c| c.sched_on_in_s),
        Some(1.0)
    );
    assert!(!rig.hw.tick(rig.at(0.5)).changed);
    assert!(rig.hw.tick(rig.at(1.0)).changed);
    assert_eq!(rig.file("power/camera"), "1");
}

#[test]
fn a_saved_state_survives_a_restart_of_the_service() {
    let mut rig = Rig::new("");
    rig.send(channel("lights", PowerChannelOp::TurnOn, 0.0), 0.0);
    rig.send(channel("camera", PowerChannelOp::TurnOff, 0.0), 0.0);
    let a = rig.send(channel("lights", PowerChannelOp::Save, 0.0), 0.0);
    assert_eq!((result(&a.reply), a.reply.value), (HardwareResult::Ok, 1));
    assert!(a.reply.message.as_str().contains("starts on"));
    assert_eq!(
        rig.hw.state(rig.t0).channel("lights").map(|c| c.saved),
        Some(1)
    );
    assert_eq!(
        rig.hw.state(rig.t0).channel("camera").map(|c| c.saved),
        Some(0)
    );
    // Toggled away from the saved state and back.
    rig.send(channel("lights", PowerChannelOp::Toggle, 0.0), 0.0);
    assert_eq!(
        rig.hw.state(rig.t0).channel("lights").map(|c| c.saved),
        Some(0)
    );
    rig.send(channel("lights", PowerChannelOp::Toggle, 0.0), 0.0);
    assert_eq!(
        rig.hw.state(rig.t0).channel("lights").map(|c| c.saved),
        Some(1)
    );
    // Schedules are volatile, saved states are not.
    rig.send(channel("lights", PowerChannelOp::ScheduleOff, 30.0), 0.0);
    rig.send(channel("lights", PowerChannelOp::TurnOff, 0.0), 0.0);

    let rig = rig.restart("");
    let s = rig.hw.state(rig.t0);
    let lights = s.channel("lights").unwrap();
    assert_eq!(
        (lights.on, lights.saved),
        (1, 1),
        "saved on overrides default off"
    );
    assert!(lights.sched_off_in_s < 0.0);
    assert_eq!(
        s.channel("camera").map(|c| (c.on, c.saved)),
        Some((1, 0)),
        "not saved: default"
    );
    assert_eq!(rig.file("power/lights"), "1");
    assert_eq!(rig.hw.next_due(rig.t0), None);
}

#[test]
fn a_save_that_cannot_be_written_is_a_backend_error() {
    let mut rig = Rig::new("");
    std::fs::create_dir_all(rig.dir.path().join("power_channels.json/blocker")).unwrap();
    let a = rig.send(channel("lights", PowerChannelOp::Save, 0.0), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::BackendError);
    assert!(a.reply.message.as_str().contains("power_channels.json"));
    assert_eq!(
        rig.hw.state(rig.t0).channel("lights").map(|c| c.saved),
        Some(0)
    );
    assert_eq!(
        rig.metric(
            "skymesh_hardware_backend_errors_total",
            "device=saved_state"
        ),
        Some(1.0)
    );
}

#[test]
fn companion_power_is_refused_without_a_command() {
    let mut rig = Rig::new("");
    for (op, what) in [
        (SystemPowerOp::PowerDown, "power_down_command"),
        (SystemPowerOp::SchedulePowerDown, "power_down_command"),
        (SystemPowerOp::PowerUp, "power_up_command"),
        (SystemPowerOp::SchedulePowerUp, "power_up_command"),
    ] {
        let a = rig.send(system(op, rig.t0.unix_s + 60.0), 0.0);
        assert_eq!(result(&a.reply), HardwareResult::Refused, "{op}");
        assert_eq!(a.reply.sub_op, SystemPowerOp::PowerDownAborted.to_wire());
        assert!(
            a.reply.message.as_str().contains(what),
            "{}",
            a.reply.message
        );
        assert!(a.effects.is_empty() && !a.changed);
    }
    let a = rig.send(system(SystemPowerOp::PowerDown, 0.0), 0.0);
    assert_eq!(
        a.reply.message.as_str(),
        "power down requested but no power_down_command is configured; refusing"
    );
    assert_eq!(rig.hw.next_due(rig.t0), None);
    assert!(rig.hw.tick(rig.at(1e6)).effects.is_empty());
    assert_eq!(
        rig.metric(
            "skymesh_hardware_requests_total",
            "op=system_power,result=refused"
        ),
        Some(5.0)
    );
}

#[test]
fn power_down_counts_down_is_abortable_and_runs_the_command() {
    let mut rig = Rig::new(WITH_COMMANDS);
    let a = rig.send(system(SystemPowerOp::PowerDown, 0.0), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::Ok);
    assert_eq!(a.reply.sub_op, SystemPowerOp::PowerDownInProgress.to_wire());
    assert_eq!(a.reply.time_remaining_s, 10.0);
    assert!(a.changed && a.effects.is_empty());
    let s = rig.hw.state(rig.at(4.0));
    assert_eq!(s.system_power, SystemPowerOp::PowerDownInProgress.to_wire());
    assert_eq!(s.system_power_in_s, 6.0);
    // Aborted in time.
    let a = rig.send(system(SystemPowerOp::PowerDownAborted, 0.0), 9.0);
    assert_eq!(result(&a.reply), HardwareResult::Ok);
    assert_eq!(a.reply.sub_op, SystemPowerOp::PowerDownAborted.to_wire());
    assert!(a.changed);
    assert!(rig.hw.tick(rig.at(20.0)).effects.is_empty());
    assert_eq!(
        rig.hw.state(rig.at(20.0)).system_power,
        SystemPowerOp::PowerDownAborted.to_wire()
    );
    let a = rig.send(system(SystemPowerOp::PowerDownAborted, 0.0), 21.0);
    assert!(!a.changed && a.reply.message.as_str().contains("nothing"));
    // Not aborted: the command is handed out exactly once, when due.
    rig.send(system(SystemPowerOp::PowerDown, 0.0), 30.0);
    assert_eq!(rig.hw.next_due(rig.at(30.0)), Some(Duration::from_secs(10)));
    assert!(rig.hw.tick(rig.at(39.9)).effects.is_empty());
    let t = rig.hw.tick(rig.at(40.0));
    assert_eq!(
        t.effects,
        vec![Effect::RunCommand {
            op: PowerCommand::PowerDown,
            argv: vec!["/sbin/poweroff".into(), "--now".into()],
        }]
    );
    assert!(t.changed);
    assert!(rig.hw.tick(rig.at(41.0)).effects.is_empty());
}

#[test]
fn scheduled_power_operations_take_a_unix_time_within_a_week() {
    let mut rig = Rig::new(WITH_COMMANDS);
    let unix = rig.t0.unix_s;
    for bad in [unix - 1.0, unix, unix + 8.0 * 86_400.0, f64::NAN] {
        let a = rig.send(system(SystemPowerOp::SchedulePowerDown, bad), 0.0);
        assert_eq!(result(&a.reply), HardwareResult::InvalidValue, "{bad}");
    }
    let a = rig.send(system(SystemPowerOp::SchedulePowerDown, unix + 60.0), 0.0);
    assert_eq!(a.reply.sub_op, SystemPowerOp::PowerDownInProgress.to_wire());
    assert_eq!(a.reply.time_remaining_s, 60.0);
    // The latest request replaces it: a power up at +30 s.
    let a = rig.send(system(SystemPowerOp::SchedulePowerUp, unix + 30.0), 0.0);
    assert_eq!(a.reply.sub_op, SystemPowerOp::PowerUpInProgress.to_wire());
    assert_eq!(a.reply.time_remaining_s, 30.0);
    let s = rig.hw.state(rig.at(10.0));
    assert_eq!(s.system_power, SystemPowerOp::PowerUpInProgress.to_wire());
    assert_eq!(s.system_power_in_s, 20.0);
    let t = rig.hw.tick(rig.at(30.0));
    assert_eq!(
        t.effects,
        vec![Effect::RunCommand {
            op: PowerCommand::PowerUp,
            argv: vec!["/usr/local/bin/wake-peripherals".into()],
        }]
    );
    assert!(
        rig.hw.tick(rig.at(60.0)).effects.is_empty(),
        "the power down was replaced"
    );
}

#[test]
fn power_up_runs_at_once() {
    let mut rig = Rig::new(WITH_COMMANDS);
    rig.send(system(SystemPowerOp::PowerDown, 0.0), 0.0);
    let a = rig.send(system(SystemPowerOp::PowerUp, 0.0), 1.0);
    assert_eq!(result(&a.reply), HardwareResult::Ok);
    assert_eq!(a.reply.sub_op, SystemPowerOp::PowerUpInProgress.to_wire());
    assert_eq!(a.reply.time_remaining_s, 0.0);
    assert_eq!(a.effects.len(), 1);
    assert!(matches!(
        &a.effects[0],
        Effect::RunCommand {
            op: PowerCommand::PowerUp,
            ..
        }
    ));
    assert_eq!(rig.hw.next_due(rig.at(1.0)), None, "the power down is gone");
}

#[test]
fn lcd_lines_are_written_cut_and_cleared() {
    let mut rig = Rig::new("");
    let a = rig.send(lcd(LcdOp::WriteLine0, "skymesh"), 0.0);
    assert_eq!((result(&a.reply), a.reply.value), (HardwareResult::Ok, 1));
    assert!(a.changed && a.reply.message.is_empty());
    let a = rig.send(lcd(LcdOp::WriteLine1, "battery 87 % ok, 12.4 V"), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::Ok);
    assert!(
        a.reply.message.as_str().contains("16 characters"),
        "{}",
        a.reply.message
    );
    assert_eq!(rig.file("lcd"), "skymesh\nbattery 87 % ok,");
    let s = rig.hw.state(rig.t0);
    assert_eq!(s.lcd_lines[0].as_str(), "skymesh");
    assert_eq!(s.lcd_lines[1].as_str(), "battery 87 % ok,");
    let a = rig.send(lcd(LcdOp::WriteLine0, "two\nlines"), 0.0);
    assert_eq!(result(&a.reply), HardwareResult::InvalidValue);
    assert_eq!(rig.hw.state(rig.t0).lcd_lines[0].as_str(), "skymesh");
    let a = rig.send(lcd(LcdOp::TurnOff, ""), 0.0);
    assert_eq!(a.reply.value, 0);
    assert_eq!(rig.file("lcd_on"), "0");
    rig.send(lcd(LcdOp::WriteLine0, "while off"), 0.0);
    assert_eq!(rig.hw.state(rig.t0).lcd_on, 0);
    rig.send(lcd(LcdOp::TurnOn, ""), 0.0);
    assert_eq!(rig.file("lcd_on"), "1");
    assert_eq!(rig.hw.state(rig.t0).lcd_lines[0].as_str(), "while off");
    let a = rig.send(lcd(LcdOp::Clear, ""), 0.0);
    assert!(a.changed);
    assert_eq!(rig.file("lcd"), "");
    let s = rig.hw.state(rig.t0);
    assert!(s.lcd_lines[0].is_empty() && s.lcd_lines[1].is_empty());
    let a = rig.send(lcd(LcdOp::Clear, ""), 0.0);
    assert!(!a.changed);
}

#[test]
fn without_an_lcd_lcd_requests_are_not_supported() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "state_dir = \"{}\"\n[lcd]\nbackend = \"none\"\n",
        dir.path().display()
    );
    let raw: RawConfig = toml::from_str(&text).unwrap();
    let settings = raw.validate_with_env(None, None).unwrap();
    let mut hw = Hardware::start(&settings, Metrics::new(&Stats::new())).unwrap();
    let now = Now {
        mono: Duration::ZERO,
        unix_s: 0.0,
    };
    let a = hw.handle(&lcd(LcdOp::WriteLine0, "x"), now);
    assert_eq!(result(&a.reply), HardwareResult::NotSupported);
    assert_eq!(hw.state(now).lcd_on, 0);
    assert!(!dir.path().join("lcd").exists());
}

#[test]
fn unreadable_requests_are_invalid_and_counted() {
    let mut rig = Rig::new(WITH_COMMANDS);
    let mut unknown_op = req(HardwareOp::LedSet, "status");
    unknown_op.op = 99;
    let cases = [
        (unknown_op, "unknown operation 99"),
        (
            HardwareRequest {
                sub_op: 8,
                ..req(HardwareOp::PowerChannel, "lights")
            },
            "power channel operation 8",
        ),
        (
            HardwareRequest {
                sub_op: 5,
                ..req(HardwareOp::Lcd, "")
            },
            "LCD operation 5",
        ),
        (
            system(SystemPowerOp::PowerDownInProgress, 0.0),
            "only appears in replies",
        ),
        (
            system(SystemPowerOp::PowerUpInProgress, 0.0),
            "only appears in replies",
        ),
        (
            HardwareRequest {
                sub_op: 7,
                ..req(HardwareOp::SystemPower, "")
            },
            "power operation 7",
        ),
    ];
    for (r, expected) in cases {
        let a = rig.send(r, 0.0);
        assert_eq!(result(&a.reply), HardwareResult::InvalidValue, "{expected}");
        assert!(
            a.reply.message.as_str().contains(expected),
            "{}",
            a.reply.message
        );
        assert_eq!(a.reply.sub_op, r.sub_op);
        assert!(!a.changed && a.effects.is_empty());
    }
    assert_eq!(
        rig.metric(
            "skymesh_hardware_requests_total",
            "op=unknown,result=invalid_value"
        ),
        Some(1.0)
    );
    assert_eq!(
        rig.metric(
            "skymesh_hardware_requests_total",
            "op=system_power,result=invalid_value"
        ),
        Some(3.0)
    );
    assert_eq!(rig.hw.next_due(rig.t0), None);
}

fn start_with(text: &str) -> Result<Hardware, StartError> {
    let raw: RawConfig = toml::from_str(text).unwrap();
    let settings = raw.validate_with_env(None, None).unwrap();
    Hardware::start(&settings, Metrics::new(&Stats::new()))
}

#[test]
fn a_missing_gpio_chip_fails_the_start_naming_the_device() {
    let dir = tempfile::tempdir().unwrap();
    let e = start_with(&format!(
        "state_dir = \"{}\"\n[[power_channel]]\nname = \"camera\"\nbackend = \"cdev\"\n\
         chip = \"/dev/gpiochip-missing\"\nline = 4\ndefault = \"on\"\n",
        dir.path().display()
    ))
    .unwrap_err();
    let text = e.to_string();
    assert!(matches!(e, StartError::Device { .. }), "{text}");
    assert!(text.contains("power channel `camera`"), "{text}");
    assert!(text.contains("/dev/gpiochip-missing"), "{text}");
}

#[test]
fn a_sysfs_led_is_driven_through_the_core() {
    let dir = tempfile::tempdir().unwrap();
    let led = dir.path().join("sys/class/leds/act");
    std::fs::create_dir_all(&led).unwrap();
    std::fs::write(led.join("max_brightness"), "1\n").unwrap();
    std::fs::write(led.join("brightness"), "1\n").unwrap();
    let mut hw = start_with(&format!(
        "state_dir = \"{}\"\n[[led]]\nname = \"act\"\nbackend = \"sysfs\"\npath = \"{}\"\n",
        dir.path().join("state").display(),
        led.display()
    ))
    .unwrap();
    let now = Now {
        mono: Duration::ZERO,
        unix_s: 0.0,
    };
    assert_eq!(
        hw.state(now).led("act").map(|l| l.value),
        Some(255),
        "read at start"
    );
    let a = hw.handle(&with_value(req(HardwareOp::LedSet, "act"), 100), now);
    assert_eq!((result(&a.reply), a.reply.value), (HardwareResult::Ok, 0));
    assert!(
        a.reply.message.as_str().contains("coarser"),
        "{}",
        a.reply.message
    );
    assert_eq!(
        std::fs::read_to_string(led.join("brightness")).unwrap(),
        "0\n"
    );
    let a = hw.handle(&with_value(req(HardwareOp::LedSet, "act"), 255), now);
    assert_eq!(a.reply.value, 255);
    assert!(a.reply.message.is_empty());
    // A missing LED directory fails the start.
    let e = start_with(&format!(
        "state_dir = \"{}\"\n[[led]]\nname = \"gone\"\nbackend = \"sysfs\"\npath = \"{}\"\n",
        dir.path().join("state").display(),
        dir.path().join("nope").display()
    ))
    .unwrap_err();
    assert!(e.to_string().contains("LED `gone`"), "{e}");
}
