//! The exception codes of a map: the native map's (Modbus's convention) and each layout's.

use crate::od::ObjError;
use crate::pdu::Exception;

/// The exception code a map answers to each reason a request is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Exceptions {
    /// No object at a register.
    pub unknown: Exception,
    /// A write to a read-only object.
    pub read_only: Exception,
    /// A value out of range (or beyond the map's scale).
    pub out_of_range: Exception,
    /// The axis moves, a run goes or a save is under way.
    pub busy: Exception,
    /// The power stage is off.
    pub disabled: Exception,
    /// A latched fault.
    pub faulted: Exception,
    /// Not in this mode or state.
    pub not_now: Exception,
    /// No trajectory within the limits.
    pub infeasible: Exception,
    /// The drive does not do this.
    pub unsupported: Exception,
    /// A read of a write-only entry.
    pub write_only: Exception,
    /// One half of a 32-bit object written alone, where the layout takes whole ones only.
    pub split: Exception,
    /// A write whose byte count is not twice its quantity.
    pub byte_count: Exception,
    /// A function the drive does not serve.
    pub function: Exception,
}

impl Exceptions {
    /// The Modbus convention: 02 address, 03 value, 04 any refusal.
    pub const MODBUS: Self = Self {
        unknown: Exception::IllegalDataAddress,
        read_only: Exception::IllegalDataAddress,
        out_of_range: Exception::IllegalDataValue,
        busy: Exception::ServerDeviceFailure,
        disabled: Exception::ServerDeviceFailure,
        faulted: Exception::ServerDeviceFailure,
        not_now: Exception::ServerDeviceFailure,
        infeasible: Exception::ServerDeviceFailure,
        unsupported: Exception::ServerDeviceFailure,
        write_only: Exception::IllegalDataAddress,
        split: Exception::IllegalDataAddress,
        byte_count: Exception::IllegalDataValue,
        function: Exception::IllegalFunction,
    };

    /// The code for a native map's `e` (a layout's window onto the native map): no such
    /// register, a value out of range, any refusal.
    pub const fn native(&self, e: Exception) -> Exception {
        match e {
            Exception::IllegalFunction | Exception::Vendor(_) => e,
            Exception::IllegalDataAddress => self.unknown,
            Exception::IllegalDataValue | Exception::ByteCount => self.out_of_range,
            Exception::ServerDeviceFailure => self.busy,
        }
    }

    /// The code for `e`.
    pub const fn of(&self, e: ObjError) -> Exception {
        match e {
            ObjError::Unknown => self.unknown,
            ObjError::ReadOnly => self.read_only,
            ObjError::OutOfRange => self.out_of_range,
            ObjError::Busy => self.busy,
            ObjError::Disabled => self.disabled,
            ObjError::Faulted => self.faulted,
            ObjError::NotNow => self.not_now,
            ObjError::Infeasible | ObjError::Overspeed => self.infeasible,
            ObjError::Unsupported => self.unsupported,
        }
    }
}
