//! Companion-computer I/O owned by the `hardware` service: LEDs, GPIO lines, power
//! channels, a two-line LCD, and the computer's own power.
//!
//! Gateways (IMC, GroundControl) never touch a device: they publish a
//! [`HardwareRequest`] on [`crate::topics::hardware_request`], the `hardware` service
//! executes it on its backend (Linux GPIO character device, `/sys/class/leds`, or the
//! simulated backend) and answers with a [`HardwareReply`] on
//! [`crate::topics::hardware_reply`] carrying the state *after* the operation. Every
//! change, and once a second, it publishes the whole [`HardwareState`] on
//! [`crate::topics::hardware_state`], so every gateway reads the same truth.
//!
//! Numbering of [`PowerChannelOp`], [`LcdOp`] and [`SystemPowerOp`] follows IMC
//! (`PowerChannelControl.op`, `LcdControl.op`, `PowerOperation.op`) so the IMC gateway
//! maps them one to one.

use iceoryx2::prelude::ZeroCopySend;

use crate::fixed::FixedStr;
use crate::header::SampleHeader;
use crate::wire_enum;

/// Longest name of an LED, GPIO line or power channel.
pub const HW_NAME_CAPACITY: usize = 32;
/// Most LEDs, GPIO lines and power channels (each) one hardware service owns.
pub const HW_MAX_ENTRIES: usize = 16;
/// Characters per LCD line carried on the bus (the display may show fewer; the
/// hardware service truncates to its configured width and says so in the reply).
pub const LCD_LINE_CAPACITY: usize = 40;

pub type HwName = FixedStr<HW_NAME_CAPACITY>;

wire_enum! {
    /// What a [`HardwareRequest`] asks for.
    pub enum HardwareOp: u8 {
        /// Set LED `name` to brightness `value` (0..=255).
        LedSet = 1 => "led_set",
        /// Report LED `name`.
        LedQuery = 2 => "led_query",
        /// Drive output line `name` to level `value` (0/1).
        GpioSet = 3 => "gpio_set",
        /// Read line `name` (inputs are read from the device, outputs report the driven level).
        GpioGet = 4 => "gpio_get",
        /// [`PowerChannelOp`] `sub_op` on channel `name`; `sched_s` seconds from now
        /// for the scheduled operations.
        PowerChannel = 5 => "power_channel",
        /// [`LcdOp`] `sub_op`; `text` for the write operations.
        Lcd = 6 => "lcd",
        /// [`SystemPowerOp`] `sub_op` for the companion computer itself; `sched_s` is
        /// seconds since the Unix epoch for the scheduled operations.
        SystemPower = 7 => "system_power",
    }
}

wire_enum! {
    /// Power channel operations, numbered as IMC `PowerChannelControl.op`.
    pub enum PowerChannelOp: u8 {
        TurnOff = 0 => "turn_off",
        TurnOn = 1 => "turn_on",
        Toggle = 2 => "toggle",
        /// Turn on in `sched_s` seconds.
        ScheduleOn = 3 => "schedule_on",
        /// Turn off in `sched_s` seconds.
        ScheduleOff = 4 => "schedule_off",
        /// Cancel the channel's scheduled operations.
        ScheduleReset = 5 => "schedule_reset",
        /// Persist the current state: it is restored when the service starts.
        Save = 6 => "save",
        /// Off, then on again after the configured restart delay.
        Restart = 7 => "restart",
    }
}

wire_enum! {
    /// LCD operations, numbered as IMC `LcdControl.op`.
    pub enum LcdOp: u8 {
        TurnOff = 0 => "turn_off",
        TurnOn = 1 => "turn_on",
        Clear = 2 => "clear",
        WriteLine0 = 3 => "write0",
        WriteLine1 = 4 => "write1",
    }
}

wire_enum! {
    /// Companion-computer power operations, numbered as IMC `PowerOperation.op`.
    /// The `*InProgress` values only appear in replies and state.
    pub enum SystemPowerOp: u8 {
        /// Power down after the configured delay (abortable meanwhile).
        PowerDown = 0 => "power_down",
        PowerDownInProgress = 1 => "power_down_in_progress",
        /// Abort a pending power down (request), or: it was aborted (reply).
        PowerDownAborted = 2 => "power_down_aborted",
        /// Power down at `sched_s` (Unix time).
        SchedulePowerDown = 3 => "schedule_power_down",
        PowerUp = 4 => "power_up",
        PowerUpInProgress = 5 => "power_up_in_progress",
        /// Power up at `sched_s` (Unix time).
        SchedulePowerUp = 6 => "schedule_power_up",
    }
}

wire_enum! {
    /// Outcome of a [`HardwareRequest`].
    pub enum HardwareResult: u8 {
        Ok = 0 => "ok",
        /// No LED / line / channel of that name is configured.
        UnknownName = 1 => "unknown_name",
        /// A value out of range, an unknown operation, or text that is not valid.
        InvalidValue = 2 => "invalid_value",
        /// The device cannot do it (e.g. setting an input line, an LCD op on a
        /// backend without it).
        NotSupported = 3 => "not_supported",
        /// The backend failed (I/O error); `message` says what.
        BackendError = 4 => "backend_error",
        /// Refused by policy (e.g. no power-down command configured).
        Refused = 5 => "refused",
    }
}

/// One request to the hardware service.
///
/// Topic: [`crate::topics::hardware_request`] (many writers, the hardware service reads).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.HardwareRequest.v1")]
#[repr(C)]
pub struct HardwareRequest {
    pub header: SampleHeader,
    /// Chosen by the requester, echoed in the [`HardwareReply`].
    pub request_id: u32,
    /// [`HardwareOp`] as stored on the wire.
    pub op: u8,
    /// [`PowerChannelOp`], [`LcdOp`] or [`SystemPowerOp`] for those ops, else 0.
    pub sub_op: u8,
    /// LED brightness or GPIO level.
    pub value: u8,
    pub reserved: u8,
    /// Seconds from now ([`HardwareOp::PowerChannel`]) or Unix time
    /// ([`HardwareOp::SystemPower`]) for scheduled operations.
    pub sched_s: f64,
    /// LED, line or channel name.
    pub name: HwName,
    /// LCD text.
    pub text: FixedStr<64>,
}
crate::assert_layout!(HardwareRequest, size = 24 + 8 + 8 + 32 + 64, align = 8);

impl HardwareRequest {
    pub fn new(request_id: u32, op: HardwareOp) -> Self {
        HardwareRequest {
            request_id,
            op: op.to_wire(),
            ..Default::default()
        }
    }

    pub fn op(&self) -> Result<HardwareOp, crate::UnknownValue> {
        HardwareOp::try_from(self.op)
    }
}

/// The answer to one [`HardwareRequest`], published by the hardware service.
///
/// Topic: [`crate::topics::hardware_reply`]. A requester keeps the replies whose
/// `requester_service`/`requester_instance` are its own header's and matches
/// `request_id`.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("skymesh.HardwareReply.v1")]
#[repr(C)]
pub struct HardwareReply {
    pub header: SampleHeader,
    pub request_id: u32,
    /// `header.service` of the request.
    pub requester_service: u16,
    /// `header.instance` of the request.
    pub requester_instance: u16,
    /// [`HardwareOp`] of the request (raw: may be an unknown value that was refused).
    pub op: u8,
    /// For power operations the resulting [`PowerChannelOp`] / [`SystemPowerOp`]
    /// (e.g. `PowerDownInProgress`, `PowerDownAborted`); else the request's.
    pub sub_op: u8,
    /// [`HardwareResult`] as stored on the wire.
    pub result: u8,
    /// State after the operation: LED brightness, GPIO level, channel on (1) / off (0).
    pub value: u8,
    /// Seconds until a pending (scheduled or delayed) operation happens; negative if none.
    pub time_remaining_s: f32,
    /// Name of the LED, line or channel (as requested).
    pub name: HwName,
    /// Human-readable detail for anything but a plain `ok`.
    pub message: FixedStr<96>,
}
crate::assert_layout!(HardwareReply, size = 24 + 16 + 32 + 96, align = 8);

impl HardwareReply {
    pub fn result(&self) -> Result<HardwareResult, crate::UnknownValue> {
        HardwareResult::try_from(self.result)
    }

    /// True if this reply answers a request published with `header`.
    pub fn answers(&self, request_header: &SampleHeader, request_id: u32) -> bool {
        self.requester_service == request_header.service
            && self.requester_instance == request_header.instance
            && self.request_id == request_id
    }
}

/// An LED and its brightness.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
pub struct LedEntry {
    pub name: HwName,
    pub value: u8,
    pub reserved: [u8; 7],
}

/// A GPIO line and its level.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
pub struct GpioEntry {
    pub name: HwName,
    pub value: u8,
    /// 1 for an output line (settable), 0 for an input.
    pub output: u8,
    pub reserved: [u8; 6],
}

/// A power channel, its state and its schedule.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct PowerChannelEntry {
    pub name: HwName,
    /// 1 on, 0 off.
    pub on: u8,
    /// 1 if the current state is the saved one (restored at start).
    pub saved: u8,
    pub reserved: [u8; 2],
    /// Seconds until a scheduled turn-on; negative if none.
    pub sched_on_in_s: f32,
    /// Seconds until a scheduled turn-off; negative if none.
    pub sched_off_in_s: f32,
    pub reserved2: u32,
}

/// Everything the hardware service owns, on every change and at 1 Hz.
///
/// Topic: [`crate::topics::hardware_state`] (latest value).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("skymesh.HardwareState.v1")]
#[repr(C)]
pub struct HardwareState {
    pub header: SampleHeader,
    pub n_leds: u8,
    pub n_gpios: u8,
    pub n_channels: u8,
    /// 1 if the LCD is on.
    pub lcd_on: u8,
    /// Pending companion power operation: [`SystemPowerOp::PowerDownInProgress`],
    /// [`SystemPowerOp::PowerUpInProgress`], or `PowerDownAborted` meaning none.
    pub system_power: u8,
    pub reserved: [u8; 3],
    /// Seconds until the pending power operation; negative if none.
    pub system_power_in_s: f32,
    pub reserved2: u32,
    pub leds: [LedEntry; HW_MAX_ENTRIES],
    pub gpios: [GpioEntry; HW_MAX_ENTRIES],
    pub channels: [PowerChannelEntry; HW_MAX_ENTRIES],
    pub lcd_lines: [FixedStr<LCD_LINE_CAPACITY>; 2],
}
crate::assert_layout!(
    HardwareState,
    size = 24 + 16 + 16 * 40 + 16 * 40 + 16 * 48 + 80,
    align = 8
);

impl Default for HardwareState {
    fn default() -> Self {
        HardwareState {
            header: SampleHeader::default(),
            n_leds: 0,
            n_gpios: 0,
            n_channels: 0,
            lcd_on: 0,
            system_power: SystemPowerOp::PowerDownAborted.to_wire(),
            reserved: [0; 3],
            system_power_in_s: -1.0,
            reserved2: 0,
            leds: [LedEntry::default(); HW_MAX_ENTRIES],
            gpios: [GpioEntry::default(); HW_MAX_ENTRIES],
            channels: [PowerChannelEntry::default(); HW_MAX_ENTRIES],
            lcd_lines: [FixedStr::EMPTY; 2],
        }
    }
}

impl HardwareState {
    /// The configured LEDs (the first `n_leds` entries).
    pub fn leds(&self) -> &[LedEntry] {
        &self.leds[..usize::from(self.n_leds).min(HW_MAX_ENTRIES)]
    }

    pub fn gpios(&self) -> &[GpioEntry] {
        &self.gpios[..usize::from(self.n_gpios).min(HW_MAX_ENTRIES)]
    }

    pub fn channels(&self) -> &[PowerChannelEntry] {
        &self.channels[..usize::from(self.n_channels).min(HW_MAX_ENTRIES)]
    }

    pub fn led(&self, name: &str) -> Option<&LedEntry> {
        self.leds().iter().find(|e| e.name.as_str() == name)
    }

    pub fn gpio(&self, name: &str) -> Option<&GpioEntry> {
        self.gpios().iter().find(|e| e.name.as_str() == name)
    }

    pub fn channel(&self, name: &str) -> Option<&PowerChannelEntry> {
        self.channels().iter().find(|e| e.name.as_str() == name)
    }
}

crate::impl_sample!(HardwareRequest, HardwareReply, HardwareState);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbering_follows_imc() {
        assert_eq!(PowerChannelOp::Restart.to_wire(), 7);
        assert_eq!(LcdOp::WriteLine1.to_wire(), 4);
        assert_eq!(SystemPowerOp::SchedulePowerUp.to_wire(), 6);
        assert!(PowerChannelOp::try_from(8).is_err());
    }

    #[test]
    fn state_lookups_only_see_configured_entries() {
        let mut s = HardwareState::default();
        s.leds[0].name = HwName::new("status");
        s.leds[0].value = 200;
        s.leds[1].name = HwName::new("ghost");
        s.n_leds = 1;
        assert_eq!(s.led("status").map(|e| e.value), Some(200));
        assert!(s.led("ghost").is_none());
        s.n_gpios = 200; // corrupt count from another process: clamped
        assert_eq!(s.gpios().len(), HW_MAX_ENTRIES);
    }

    #[test]
    fn replies_match_their_request() {
        let mut h = SampleHeader {
            service: 12,
            instance: 0,
            ..Default::default()
        };
        let reply = HardwareReply {
            request_id: 7,
            requester_service: 12,
            ..Default::default()
        };
        assert!(reply.answers(&h, 7));
        assert!(!reply.answers(&h, 8));
        h.instance = 1;
        assert!(!reply.answers(&h, 7));
    }
}
