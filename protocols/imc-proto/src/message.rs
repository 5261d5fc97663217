//! The IMC messages skymesh speaks (ids and field order from `specs/FACTS.md`).
//!
//! Enumerated fields are typed: a value outside the enumeration is a decode error
//! ([`crate::DecodeError::InvalidValue`]), never a silently wrong command.

/// IMC message ids.
pub mod ids {
    pub const HEARTBEAT: u16 = 150;
    pub const ANNOUNCE: u16 = 151;
    pub const CAMERA_ZOOM: u16 = 300;
    pub const SET_THRUSTER_ACTUATION: u16 = 301;
    pub const SET_SERVO_POSITION: u16 = 302;
    pub const SET_CONTROL_SURFACE_DEFLECTION: u16 = 303;
    pub const REMOTE_ACTIONS_REQUEST: u16 = 304;
    pub const REMOTE_ACTIONS: u16 = 305;
    pub const BUTTON_EVENT: u16 = 306;
    pub const LCD_CONTROL: u16 = 307;
    pub const POWER_OPERATION: u16 = 308;
    pub const POWER_CHANNEL_CONTROL: u16 = 309;
    pub const QUERY_POWER_CHANNEL_STATE: u16 = 310;
    pub const POWER_CHANNEL_STATE: u16 = 311;
    pub const LED_BRIGHTNESS: u16 = 312;
    pub const QUERY_LED_BRIGHTNESS: u16 = 313;
    pub const SET_LED_BRIGHTNESS: u16 = 314;
    pub const SET_PWM: u16 = 315;
    pub const PWM: u16 = 316;
    pub const GPIO_STATE: u16 = 2000;
    pub const GPIO_STATE_GET: u16 = 2001;
    pub const GPIO_STATE_SET: u16 = 2002;
}

macro_rules! imc_enum {
    ($(#[$meta:meta])* $name:ident { $($(#[$vmeta:meta])* $variant:ident = $value:expr),+ $(,)? }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[repr(u8)]
        pub enum $name { $($(#[$vmeta])* $variant = $value),+ }

        impl $name {
            pub const ALL: &'static [$name] = &[$($name::$variant),+];
            pub const fn to_u8(self) -> u8 { self as u8 }
        }

        impl TryFrom<u8> for $name {
            type Error = u8;
            fn try_from(v: u8) -> Result<Self, u8> {
                match v {
                    $(x if x == $value => Ok($name::$variant),)+
                    other => Err(other),
                }
            }
        }
    };
}

imc_enum! {
    /// `Announce.sys_type`.
    SystemType { Ccu = 0, HumanSensor = 1, Uuv = 2, Usv = 3, Uav = 4, Ugv = 5, StaticSensor = 6, MobileSensor = 7, Wsn = 8 }
}
imc_enum! {
    /// `CameraZoom.action`.
    ZoomAction { Reset = 0, In = 1, Out = 2, Stop = 3 }
}
imc_enum! {
    /// `RemoteActionsRequest.op`.
    RemoteActionsOp { Report = 0, Query = 1, Register = 2 }
}
imc_enum! {
    /// `LcdControl.op`.
    LcdOperation { TurnOff = 0, TurnOn = 1, Clear = 2, Write0 = 3, Write1 = 4 }
}
imc_enum! {
    /// `PowerOperation.op`.
    PowerOp { PowerDown = 0, PowerDownInProgress = 1, PowerDownAborted = 2, SchedulePowerDown = 3, PowerUp = 4, PowerUpInProgress = 5, SchedulePowerUp = 6 }
}
imc_enum! {
    /// `PowerChannelControl.op`.
    ChannelOp { TurnOff = 0, TurnOn = 1, Toggle = 2, ScheduleOn = 3, ScheduleOff = 4, ScheduleReset = 5, Save = 6, Restart = 7 }
}
imc_enum! {
    /// `PowerChannelState.state`.
    ChannelState { Off = 0, On = 1 }
}

/// `Announce` (151): who a system is and how to reach it.
#[derive(Debug, Clone, PartialEq)]
pub struct Announce {
    pub sys_name: String,
    pub sys_type: SystemType,
    pub owner: u16,
    /// Radians (WGS-84).
    pub lat: f64,
    /// Radians (WGS-84).
    pub lon: f64,
    /// Metres (height above the WGS-84 ellipsoid).
    pub height: f32,
    /// `;`-separated service URIs, e.g. `imc+udp://10.0.0.5:6002/`.
    pub services: String,
}

/// One IMC message of the set skymesh implements.
#[derive(Debug, Clone, PartialEq)]
pub enum Message {
    Heartbeat,
    Announce(Announce),
    CameraZoom {
        id: u8,
        zoom: u8,
        action: ZoomAction,
    },
    SetThrusterActuation {
        id: u8,
        value: f32,
    },
    SetServoPosition {
        id: u8,
        value: f32,
    },
    SetControlSurfaceDeflection {
        id: u8,
        angle: f32,
    },
    RemoteActionsRequest {
        op: RemoteActionsOp,
        actions: String,
    },
    RemoteActions {
        actions: String,
    },
    ButtonEvent {
        button: u8,
        value: u8,
    },
    LcdControl {
        op: LcdOperation,
        text: String,
    },
    PowerOperation {
        op: PowerOp,
        time_remain: f32,
        sched_time: f64,
    },
    PowerChannelControl {
        name: String,
        op: ChannelOp,
        sched_time: f64,
    },
    QueryPowerChannelState,
    PowerChannelState {
        name: String,
        state: ChannelState,
    },
    LedBrightness {
        name: String,
        value: u8,
    },
    QueryLedBrightness {
        name: String,
    },
    SetLedBrightness {
        name: String,
        value: u8,
    },
    SetPwm {
        id: u8,
        period: u32,
        duty_cycle: u32,
    },
    Pwm {
        id: u8,
        period: u32,
        duty_cycle: u32,
    },
    GpioState {
        name: String,
        value: u8,
    },
    GpioStateGet {
        name: String,
    },
    GpioStateSet {
        name: String,
        value: u8,
    },
}
