//! Newtypes that carry the unit of a number, and the control tick's rate.

use core::fmt;

/// Control ticks per second. At 20 kHz a tick is 50 µs: at the manual's top speed of 200 kpps
/// that is 10 steps per tick, which the output stage spaces from the setpoint's velocity and
/// fraction; at low speed the sub-microstep setpoint is smooth. It is also the rate the closed
/// loop wants, and on a 170 MHz Cortex-M4 it leaves 8500 cycles per tick.
pub const TICK_HZ: u32 = 20_000;
/// The control tick period in microseconds.
pub const TICK_MICROS: u64 = 1_000_000 / TICK_HZ as u64;

/// Full steps a revolution of the motors the drive runs (1.8°), for units per revolution.
pub const FULL_STEPS_PER_REV: i64 = 200;

/// A point in time in microseconds since the drive started. Wraps after 584 000 years.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Instant(u64);

impl Instant {
    /// The instant `us` microseconds after start.
    pub const fn from_micros(us: u64) -> Self {
        Self(us)
    }
    /// Microseconds since start.
    pub const fn as_micros(self) -> u64 {
        self.0
    }
    /// Microseconds from `earlier` to `self`, 0 if `earlier` is later (clocks never run back).
    pub const fn since(self, earlier: Instant) -> u64 {
        self.0.saturating_sub(earlier.0)
    }
    /// This instant plus `us` microseconds.
    pub const fn plus_micros(self, us: u64) -> Self {
        Self(self.0.saturating_add(us))
    }
}

/// A Modbus slave address: 1-247 address one node, 0 is the broadcast address.
///
/// ```
/// use drive_core::SlaveAddr;
/// assert!(SlaveAddr::BROADCAST.is_broadcast());
/// assert_eq!(SlaveAddr::new(127).map(SlaveAddr::get), Some(127));
/// assert_eq!(SlaveAddr::new(248), None);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct SlaveAddr(u8);

impl SlaveAddr {
    /// The broadcast address 0: every slave executes, none answers.
    pub const BROADCAST: Self = Self(0);
    /// Address `a` if Modbus allows it (0-247).
    pub const fn new(a: u8) -> Option<Self> {
        if a <= 247 { Some(Self(a)) } else { None }
    }
    /// The address byte.
    pub const fn get(self) -> u8 {
        self.0
    }
    /// Whether this is the broadcast address 0.
    pub const fn is_broadcast(self) -> bool {
        self.0 == 0
    }
}

impl fmt::Display for SlaveAddr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

/// A serial line speed in bits per second, one of the rates the drive supports.
///
/// ```
/// use drive_core::Baud;
/// let b = Baud::new(9600).unwrap();
/// // 11-bit characters: t1.5 = 1.5 * 11 / 9600 s, t3.5 = 3.5 * 11 / 9600 s.
/// assert_eq!((b.t15_micros(), b.t35_micros()), (1718, 4010));
/// // Above 19200 baud the Modbus serial-line spec fixes them.
/// let fast = Baud::new(115_200).unwrap();
/// assert_eq!((fast.t15_micros(), fast.t35_micros()), (750, 1750));
/// assert!(Baud::new(1200).is_none());
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Baud(u32);

impl Baud {
    /// The rates of object 0x202A: the manual's list (including its 51200) plus the standard 57600.
    pub const SUPPORTED: [u32; 7] = [4800, 9600, 19200, 38400, 51200, 57600, 115_200];
    /// The factory rate.
    pub const FACTORY: Self = Self(9600);

    /// `bps` if the drive supports it.
    pub fn new(bps: u32) -> Option<Self> {
        Self::SUPPORTED.contains(&bps).then_some(Self(bps))
    }
    /// Bits per second.
    pub const fn get(self) -> u32 {
        self.0
    }
    /// Inter-character timeout t1.5 in microseconds (rounded down).
    pub const fn t15_micros(self) -> u64 {
        if self.0 > 19200 { 750 } else { 16_500_000 / self.0 as u64 }
    }
    /// Inter-frame silence t3.5 in microseconds (rounded down).
    pub const fn t35_micros(self) -> u64 {
        if self.0 > 19200 { 1750 } else { 38_500_000 / self.0 as u64 }
    }
}
