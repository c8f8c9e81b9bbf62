//! The drive's work modes, PVT modes and power states as enums: the numbers are the native map's values.

/// The work mode (0x6007): what the motion objects command.
///
/// ```
/// use drive_core::modes::WorkMode;
/// assert_eq!(WorkMode::from_raw(4), Some(WorkMode::ProfilePosition));
/// assert_eq!(WorkMode::from_raw(3), Some(WorkMode::Follow));
/// assert_eq!(WorkMode::from_raw(7), None);
/// assert_eq!(WorkMode::Pvt.raw(), 2);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum WorkMode {
    /// Position mode (0): relative and absolute moves at the maximum speed 0x6003.
    #[default]
    Position = 0,
    /// Velocity mode (1): 0x6003 is the speed to run at, 0 stops.
    Velocity = 1,
    /// PVT mode (2): runs of stored or streamed position-velocity-time points.
    Pvt = 2,
    /// Pulse following (3, the manual's encoder follower): the setpoint follows the pulse input
    /// (STEP/DIR, CW/CCW or an encoder's A/B as 0x21B7 says), one microstep a pulse.
    Follow = 3,
    /// Profile position (4, CiA 402 PP): set-points by the controlword's handshake.
    ProfilePosition = 4,
    /// Profile velocity (5, CiA 402 PV).
    ProfileVelocity = 5,
    /// Homing (6, CiA 402's homing mode, ours): the device controlword's bit 4 starts the homing
    /// of 0x2160, bit 8 halts it.
    Homing = 6,
}

impl WorkMode {
    /// Every mode.
    pub const ALL: [Self; 7] = [
        Self::Position,
        Self::Velocity,
        Self::Pvt,
        Self::Follow,
        Self::ProfilePosition,
        Self::ProfileVelocity,
        Self::Homing,
    ];
    /// Every mode's value, for the object's declared set.
    pub const RAW: [u32; 7] = [0, 1, 2, 3, 4, 5, 6];

    /// The mode of a register value, if it is one.
    pub const fn from_raw(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Position),
            1 => Some(Self::Velocity),
            2 => Some(Self::Pvt),
            3 => Some(Self::Follow),
            4 => Some(Self::ProfilePosition),
            5 => Some(Self::ProfileVelocity),
            6 => Some(Self::Homing),
            _ => None,
        }
    }

    /// The register value.
    pub const fn raw(self) -> u32 {
        self as u32
    }

    /// Whether the CiA 402 controlword and statusword apply (PP and PV).
    pub const fn is_profile(self) -> bool {
        matches!(self, Self::ProfilePosition | Self::ProfileVelocity)
    }
}

/// The PVT mode (0x6018): where a run's points come from. The manual numbers them 1-3.
///
/// ```
/// use drive_core::modes::PvtMode;
/// assert_eq!(PvtMode::from_raw(2), Some(PvtMode::Fifo));
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PvtMode {
    /// One phase of the table, run once (the manual's mode 1).
    #[default]
    Single = 0,
    /// Acceleration, loop and deceleration phases of the table (mode 2).
    Phases = 1,
    /// A FIFO the master refills while the run goes (mode 3).
    Fifo = 2,
}

impl PvtMode {
    /// The mode of a register value, if it is one.
    pub const fn from_raw(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Single),
            1 => Some(Self::Phases),
            2 => Some(Self::Fifo),
            _ => None,
        }
    }
}

/// How the pulse input's two lines carry the pulses (our object 0x21B7; seed 002's 0244).
///
/// ```
/// use drive_core::modes::PulseFormat;
/// assert_eq!(PulseFormat::from_raw(2), Some(PulseFormat::CwCcw));
/// assert_eq!(PulseFormat::Quadrature.raw(), 3);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PulseFormat {
    /// Pulse and direction (1): a rising edge on STEP is a pulse, DIR high counts it down.
    #[default]
    StepDir = 1,
    /// Double pulse (2): a rising edge on CW counts up, one on CCW down.
    CwCcw = 2,
    /// An encoder's quadrature signals A and B (3): every edge of either counts, the phase
    /// between them giving the direction.
    Quadrature = 3,
}

impl PulseFormat {
    /// The format of a register value, if it is one.
    pub const fn from_raw(v: u32) -> Option<Self> {
        match v {
            1 => Some(Self::StepDir),
            2 => Some(Self::CwCcw),
            3 => Some(Self::Quadrature),
            _ => None,
        }
    }

    /// The register value.
    pub const fn raw(self) -> u32 {
        self as u32
    }
}

/// What the power stage does, and why.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PowerState {
    /// Driving the motor.
    On,
    /// Off because the master disabled it (0x6011 = 0).
    Disabled,
    /// Off because a fault is latched (0x6000 or 0x2135) until the master clears it.
    Faulted,
    /// Off because the supply fell below the free-wheel voltage (0x6083) of the power-loss
    /// behaviour; on again when it recovers.
    Freed,
}

#[cfg(test)]
mod tests {
    use super::WorkMode;

    #[test]
    fn every_mode_round_trips_and_raw_lists_them() {
        for (m, raw) in WorkMode::ALL.iter().zip(WorkMode::RAW) {
            assert_eq!(m.raw(), raw);
            assert_eq!(WorkMode::from_raw(raw), Some(*m));
        }
    }
}

/// A motion command (our object 0x21A0; the numbers are seed 002's control command 0323).
///
/// ```
/// use drive_core::modes::Command;
/// assert_eq!(Command::from_raw(4), Some(Command::JogPositive));
/// assert_eq!(Command::from_raw(9), None);
/// assert_eq!(Command::Home.raw(), 12);
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Command {
    /// Nothing (0).
    #[default]
    None = 0,
    /// Run to the command target (1).
    Absolute = 1,
    /// Run by the command target (2).
    Relative = 2,
    /// Run at the run velocity (3).
    Velocity = 3,
    /// Jog in the positive direction (4).
    JogPositive = 4,
    /// Jog in the negative direction (5).
    JogNegative = 5,
    /// Decelerate to a stop (6).
    Stop = 6,
    /// Stop at the quick-stop deceleration (7).
    EmergencyStop = 7,
    /// Set the position to the preset (8).
    SetPosition = 8,
    /// Home (12).
    Home = 12,
    /// Clear the alarms (13).
    AlarmClear = 13,
    /// Check the multi-segment program (14).
    ProgramCheck = 14,
    /// Save the multi-segment program with the parameters (15).
    ProgramSave = 15,
    /// Start the selected program segment, or resume a paused one (16).
    ProgramStart = 16,
    /// Pause the running program segment (17).
    ProgramPause = 17,
    /// End the running program segment (18).
    ProgramEnd = 18,
    /// Go on with the next position data group now, whatever the waiting group's step-change
    /// conditions (19; seed 004's POS-STEP).
    ProgramStep = 19,
}

impl Command {
    /// Every command's value, for the object's declared set.
    pub const RAW: [u32; 17] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 13, 14, 15, 16, 17, 18, 19];

    /// The command of a register value, if it is one.
    pub const fn from_raw(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::None,
            1 => Self::Absolute,
            2 => Self::Relative,
            3 => Self::Velocity,
            4 => Self::JogPositive,
            5 => Self::JogNegative,
            6 => Self::Stop,
            7 => Self::EmergencyStop,
            8 => Self::SetPosition,
            12 => Self::Home,
            13 => Self::AlarmClear,
            14 => Self::ProgramCheck,
            15 => Self::ProgramSave,
            16 => Self::ProgramStart,
            17 => Self::ProgramPause,
            18 => Self::ProgramEnd,
            19 => Self::ProgramStep,
            _ => return None,
        })
    }

    /// The register value.
    pub const fn raw(self) -> u32 {
        self as u32
    }

    /// Whether the command plans a motion (a run or a stop) on the axis.
    pub const fn plans(self) -> bool {
        matches!(
            self,
            Self::Absolute
                | Self::Relative
                | Self::Velocity
                | Self::JogPositive
                | Self::JogNegative
                | Self::Stop
                | Self::EmergencyStop
        )
    }
}

/// What the running motion command is, for the writes that change it on line (seed 002: a new
/// target re-targets an absolute run, a new velocity changes a run's speed).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Running {
    /// No motion command runs (or another motion replaced it).
    #[default]
    Nothing,
    /// An absolute run.
    Absolute,
    /// A relative run.
    Relative,
    /// A run at the run velocity.
    Velocity,
    /// A jog.
    Jog,
}
