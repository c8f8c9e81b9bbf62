//! The drive's power state machine: CiA 402's device states, driven by a controlword.
//!
//! Every map reaches the same machine. A CiA 402 map writes its controlword ([`Command`]s,
//! decoded by [`Command::decode`]); the native map's enable 0x6011 is a shortcut through it (1
//! goes to operation enabled, 0 to switch on disabled); a fault takes any state to
//! [`DeviceState::Fault`]. The motor is energised in operation enabled and quick stop active
//! only: a stepper holds its position with current, and a master that has not enabled the
//! operation expects a free shaft.
//!
//! ```
//! use drive_core::power::{Command, DeviceState};
//! let s = DeviceState::SwitchOnDisabled;
//! let s = s.on(Command::decode(0x06)).unwrap(); // shutdown
//! let s = s.on(Command::decode(0x07)).unwrap(); // switch on
//! let s = s.on(Command::decode(0x0F)).unwrap(); // enable operation
//! assert_eq!(s, DeviceState::OperationEnabled);
//! assert_eq!(s.statusword(), 0x0037);
//! // Switch on straight from switch on disabled is not in the table.
//! assert_eq!(DeviceState::SwitchOnDisabled.on(Command::decode(0x07)), None);
//! ```

/// CiA 402's device states (the statusword's low bits tell them apart).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DeviceState {
    /// Initialising: left on its own for switch on disabled at power-up.
    NotReadyToSwitchOn,
    /// The power stage is off and may not be switched on until a shutdown command.
    #[default]
    SwitchOnDisabled,
    /// Ready: a switch-on command may follow.
    ReadyToSwitchOn,
    /// Switched on, the drive function not yet enabled (the motor is not energised).
    SwitchedOn,
    /// The motor is energised and moves on command.
    OperationEnabled,
    /// A quick stop: the axis decelerates at the quick-stop deceleration, then (by the quick
    /// stop option) leaves for switch on disabled or stays here.
    QuickStopActive,
    /// A fault was detected and its reaction runs (the drive's is immediate: the power stage off).
    FaultReactionActive,
    /// A fault is latched: the power stage is off until a fault reset.
    Fault,
}

/// A controlword command (CiA 402's table of bits 0-3 and 7).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Command {
    /// `0xxx x110`: to ready to switch on.
    Shutdown,
    /// `0xxx 0111`: to switched on (also "disable operation" from operation enabled).
    SwitchOn,
    /// `0xxx 1111`: to operation enabled (from ready to switch on through switched on).
    EnableOperation,
    /// `0xxx xx0x`: to switch on disabled.
    DisableVoltage,
    /// `0xxx x01x`: quick stop.
    QuickStop,
    /// Bit 7 set: fault reset (on its rising edge; a held bit 7 commands nothing more).
    FaultReset,
}

impl Command {
    /// The command of a controlword's bits (CiA 402 table 31; bit 7 wins).
    pub const fn decode(cw: u16) -> Self {
        if cw & 0x80 != 0 {
            Self::FaultReset
        } else if cw & 0x02 == 0 {
            Self::DisableVoltage
        } else if cw & 0x04 == 0 {
            Self::QuickStop
        } else if cw & 0x01 == 0 {
            Self::Shutdown
        } else if cw & 0x08 == 0 {
            Self::SwitchOn
        } else {
            Self::EnableOperation
        }
    }
}

/// Statusword bit 0: ready to switch on.
pub const SW_READY: u16 = 1 << 0;
/// Statusword bit 1: switched on.
pub const SW_SWITCHED_ON: u16 = 1 << 1;
/// Statusword bit 2: operation enabled.
pub const SW_OPERATION_ENABLED: u16 = 1 << 2;
/// Statusword bit 3: fault.
pub const SW_FAULT: u16 = 1 << 3;
/// Statusword bit 4: voltage enabled (the supply is present and the power stage may switch on).
pub const SW_VOLTAGE_ENABLED: u16 = 1 << 4;
/// Statusword bit 5: quick stop, active low (0 while a quick stop is active).
pub const SW_QUICK_STOP: u16 = 1 << 5;
/// Statusword bit 6: switch on disabled.
pub const SW_SWITCH_ON_DISABLED: u16 = 1 << 6;
/// The statusword bits that tell the states apart.
pub const SW_STATE_MASK: u16 = 0x006F;

impl DeviceState {
    /// The state a command leads to, or `None` where CiA 402's table has no such transition
    /// (the command is ignored). A fault reset outside the fault state does nothing.
    pub const fn on(self, cmd: Command) -> Option<Self> {
        use Command as C;
        use DeviceState as S;
        Some(match (self, cmd) {
            // 2, 6, 8
            (S::SwitchOnDisabled | S::SwitchedOn | S::OperationEnabled, C::Shutdown) => S::ReadyToSwitchOn,
            // 3, 5
            (S::ReadyToSwitchOn | S::OperationEnabled, C::SwitchOn) => S::SwitchedOn,
            // 4, 3+4 (most drives take 0x0F from ready to switch on), 16 (quick stop options 5-8),
            // and 2+3+4 from switch on disabled: JMC's routines (seed 001 §6) write 0x000F alone
            // after power-up.
            (S::SwitchOnDisabled | S::ReadyToSwitchOn | S::SwitchedOn | S::QuickStopActive, C::EnableOperation) => {
                S::OperationEnabled
            }
            // 7, 9, 10, 12
            (S::ReadyToSwitchOn | S::SwitchedOn | S::OperationEnabled | S::QuickStopActive, C::DisableVoltage) => {
                S::SwitchOnDisabled
            }
            // 7, 10
            (S::ReadyToSwitchOn | S::SwitchedOn, C::QuickStop) => S::SwitchOnDisabled,
            // 11
            (S::OperationEnabled, C::QuickStop) => S::QuickStopActive,
            // 15
            (S::Fault, C::FaultReset) => S::SwitchOnDisabled,
            // Held commands: no transition, nothing to refuse.
            _ => return None,
        })
    }

    /// The statusword's state bits (0-6).
    pub const fn statusword(self) -> u16 {
        match self {
            Self::NotReadyToSwitchOn => 0,
            Self::SwitchOnDisabled => SW_SWITCH_ON_DISABLED,
            Self::ReadyToSwitchOn => SW_READY | SW_QUICK_STOP | SW_VOLTAGE_ENABLED,
            Self::SwitchedOn => SW_READY | SW_SWITCHED_ON | SW_QUICK_STOP | SW_VOLTAGE_ENABLED,
            Self::OperationEnabled => {
                SW_READY | SW_SWITCHED_ON | SW_OPERATION_ENABLED | SW_QUICK_STOP | SW_VOLTAGE_ENABLED
            }
            Self::QuickStopActive => SW_READY | SW_SWITCHED_ON | SW_OPERATION_ENABLED | SW_VOLTAGE_ENABLED,
            Self::FaultReactionActive => SW_READY | SW_SWITCHED_ON | SW_OPERATION_ENABLED | SW_FAULT,
            Self::Fault => SW_FAULT,
        }
    }

    /// Whether the motor is energised in this state.
    pub const fn energised(self) -> bool {
        matches!(self, Self::OperationEnabled | Self::QuickStopActive)
    }
}

/// What a quick stop does (CiA 402's quick stop option code, 0x605A).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum QuickStopOption {
    /// 0: the power stage off at once, the shaft free; to switch on disabled.
    Disable,
    /// 1: decelerate at the profile's deceleration, then to switch on disabled.
    SlowDown,
    /// 2: decelerate at the quick-stop deceleration, then to switch on disabled.
    #[default]
    QuickStop,
    /// 5: decelerate at the profile's deceleration and stay in quick stop active.
    SlowDownStay,
    /// 6: decelerate at the quick-stop deceleration and stay in quick stop active.
    QuickStopStay,
    /// -1 (0xFFFF, manufacturer-specific): stop at once, energised, then to switch on disabled.
    Immediate,
}

impl QuickStopOption {
    /// Every option's code, for the object's declared set.
    pub const RAW: [u32; 6] = [0, 1, 2, 5, 6, 0xFFFF];

    /// The option of a register value, if it is one.
    pub const fn from_raw(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Disable),
            1 => Some(Self::SlowDown),
            2 => Some(Self::QuickStop),
            5 => Some(Self::SlowDownStay),
            6 => Some(Self::QuickStopStay),
            0xFFFF => Some(Self::Immediate),
            _ => None,
        }
    }

    /// Whether the axis stays in quick stop active once at rest.
    pub const fn stays(self) -> bool {
        matches!(self, Self::SlowDownStay | Self::QuickStopStay)
    }

    /// Whether it brakes at the quick-stop deceleration (rather than the profile's).
    pub const fn quick(self) -> bool {
        matches!(self, Self::QuickStop | Self::QuickStopStay)
    }
}

#[cfg(test)]
mod tests {
    use super::{Command, DeviceState};

    #[test]
    fn decode_follows_the_table() {
        assert_eq!(Command::decode(0x0006), Command::Shutdown);
        assert_eq!(Command::decode(0x000E), Command::Shutdown);
        assert_eq!(Command::decode(0x0007), Command::SwitchOn);
        assert_eq!(Command::decode(0x000F), Command::EnableOperation);
        assert_eq!(Command::decode(0x0000), Command::DisableVoltage);
        assert_eq!(Command::decode(0x000D), Command::DisableVoltage);
        assert_eq!(Command::decode(0x0002), Command::QuickStop);
        assert_eq!(Command::decode(0x000B), Command::QuickStop);
        assert_eq!(Command::decode(0x0080), Command::FaultReset);
        assert_eq!(Command::decode(0x008F), Command::FaultReset);
    }

    #[test]
    fn states_have_distinct_statuswords() {
        use DeviceState as S;
        let all = [
            S::NotReadyToSwitchOn,
            S::SwitchOnDisabled,
            S::ReadyToSwitchOn,
            S::SwitchedOn,
            S::OperationEnabled,
            S::QuickStopActive,
            S::FaultReactionActive,
            S::Fault,
        ];
        for (i, a) in all.iter().enumerate() {
            for b in all.iter().skip(i + 1) {
                assert_ne!(a.statusword() & super::SW_STATE_MASK, b.statusword() & super::SW_STATE_MASK);
            }
        }
    }
}
