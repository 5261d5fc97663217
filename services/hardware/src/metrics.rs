//! The metrics of the hardware service, exported through the runtime's stats sample.
//!
//! | series | labels | meaning |
//! |---|---|---|
//! | `skymesh_hardware_requests_total` | op, result | requests answered (op `unknown` when unreadable) |
//! | `skymesh_hardware_backend_errors_total` | device | failed device operations (led, gpio, power_channel, lcd, saved_state) |
//! | `skymesh_hardware_power_channel_on` | channel | 1 while the channel is on |
//! | `skymesh_hardware_power_commands_total` | op, result | companion power commands run (ok, failed, not_started) |
//!
//! Label sets are bounded: ops and results are the bus enums' names, channels come
//! from the config (at most 16). Counter series are registered on first use.

use skymesh_ipc_types::{HardwareOp, HardwareResult};
use skymesh_runtime::{CounterFamily, Gauge, Stats};

/// The device kind of a backend error (label `device`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Device {
    Led,
    Gpio,
    PowerChannel,
    Lcd,
    /// The saved power-channel states file.
    SavedState,
}

impl Device {
    pub fn as_str(self) -> &'static str {
        match self {
            Device::Led => "led",
            Device::Gpio => "gpio",
            Device::PowerChannel => "power_channel",
            Device::Lcd => "lcd",
            Device::SavedState => "saved_state",
        }
    }
}

/// Every series the service exports. Cheap to clone.
#[derive(Debug, Clone)]
pub struct Metrics {
    stats: Stats,
    requests: CounterFamily,
    backend_errors: CounterFamily,
    power_commands: CounterFamily,
}

impl Metrics {
    pub fn new(stats: &Stats) -> Self {
        Metrics {
            stats: stats.clone(),
            requests: CounterFamily::new(
                stats,
                "skymesh_hardware_requests_total",
                ("op", Some("result")),
            ),
            backend_errors: CounterFamily::new(
                stats,
                "skymesh_hardware_backend_errors_total",
                ("device", None),
            ),
            power_commands: CounterFamily::new(
                stats,
                "skymesh_hardware_power_commands_total",
                ("op", Some("result")),
            ),
        }
    }

    /// One answered request; `op` is `None` when it could not be read.
    pub fn request(&self, op: Option<HardwareOp>, result: HardwareResult) {
        let op = op.map_or("unknown", HardwareOp::as_str);
        self.requests.get(op, result.as_str()).inc();
    }

    pub fn backend_error(&self, device: Device) {
        self.backend_errors.inc(device.as_str());
    }

    /// The `skymesh_hardware_power_channel_on{channel}` gauge.
    pub fn channel_gauge(&self, channel: &str) -> Gauge {
        self.stats
            .gauge("skymesh_hardware_power_channel_on", &[("channel", channel)])
    }

    /// A companion power command: `op` is `power_down` / `power_up`, `result` is `ok`
    /// (exit 0), `failed` (other exit) or `not_started`.
    pub fn power_command(&self, op: &'static str, result: &'static str) {
        self.power_commands.get(op, result).inc();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skymesh_ipc_types::ServiceStats;

    #[test]
    fn series_have_the_documented_names_and_labels() {
        let stats = Stats::new();
        let m = Metrics::new(&stats);
        m.request(Some(HardwareOp::LedSet), HardwareResult::Ok);
        m.request(None, HardwareResult::InvalidValue);
        m.backend_error(Device::PowerChannel);
        m.channel_gauge("camera").set(1.0);
        m.power_command("power_down", "ok");
        let mut out = Box::<ServiceStats>::default();
        stats.snapshot_into(&mut out);
        let find = |name: &str, labels: &str| {
            out.entries()
                .iter()
                .find(|e| e.name.as_str() == name && e.labels.as_str() == labels)
                .map(|e| e.value)
        };
        assert_eq!(
            find("skymesh_hardware_requests_total", "op=led_set,result=ok"),
            Some(1.0)
        );
        assert_eq!(
            find(
                "skymesh_hardware_requests_total",
                "op=unknown,result=invalid_value"
            ),
            Some(1.0)
        );
        assert_eq!(
            find(
                "skymesh_hardware_backend_errors_total",
                "device=power_channel"
            ),
            Some(1.0)
        );
        assert_eq!(
            find("skymesh_hardware_power_channel_on", "channel=camera"),
            Some(1.0)
        );
        assert_eq!(
            find(
                "skymesh_hardware_power_commands_total",
                "op=power_down,result=ok"
            ),
            Some(1.0)
        );
    }
}
