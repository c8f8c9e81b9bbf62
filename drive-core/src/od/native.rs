//! The drive's native objects (seed 000, MSME/PMC007): chapter 5 and appendix 1, with the
//! corrections of the project's spec notes. Addresses are the native Modbus register numbers.
//!
//! Our own objects sit in the vendor range 0x2100..=0x21FF.

#[cfg(feature = "docs")]
use super::Unit;
use super::{
    Access::*,
    ObjectDef, Range,
    Range::{Any, Bits, Magnitude, Set, Span},
    Storage::*,
    Type::*,
};

/// Encoder resolutions of 0x6054: counts per revolution, or 12 (bits) for the absolute encoder.
const ENCODER_CPR: &[u32] = &[12, 200, 400, 500, 600, 800, 1000, 1200, 1600];
/// Modes of 0x6007.
const MODES: &[u32] = &crate::modes::WorkMode::RAW;
/// The homing methods 0x2160 takes (as the register holds them: -1 is 0xFFFF).
const HOMING_METHODS: [u32; 26] = [
    1, 2, 3, 4, 5, 6, 17, 18, 19, 20, 21, 22, 33, 34, 35, 37, 0xFFFF, 0xFFFE, 0xFFFD, 0xFFFC, 0xFFFB, 0xFFFA, 0xFFF9,
    0xFFF8, 0xFFF7, 0xFFF6,
];
/// The functions an input takes (0x21BA-0x21C0): the motion commands, the limit and home
/// switches, enable.
const INPUT_FUNCTIONS: &[u32] =
    &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 25, 26, 27, 28, 29];
/// The values of 0x21F1: baud rate digit 0-5, framing digit 0-5.
const SERIAL_FORMATS: [u32; 36] = {
    let mut v = [0u32; 36];
    let mut i = 0;
    while i < 36 {
        #[allow(clippy::indexing_slicing)] // const evaluation: out of bounds is a compile error
        {
            v[i] = ((i as u32 / 6) << 4) | (i as u32 % 6);
        }
        i += 1;
    }
    v
};
/// A PVT table index or count.
const PVT_INDEX: Range = Span(0, 1000);
/// Full signed 32-bit range.
const S32_ANY: Range = Span(i32::MIN, i32::MAX);

macro_rules! objects {
    ($(
        $(#[doc = $doc:literal])*
        $id:ident @ $addr:literal : $ty:expr, $acc:ident, $sto:ident, $range:expr, default $def:expr, $unit:ident, $name:literal;
    )*) => {
        /// An object of the drive. The discriminant is the object's index in [`OBJECTS`].
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        #[repr(u16)]
        pub enum Obj {
            $( $(#[doc = $doc])* $id, )*
        }

        /// Every object, in register order.
        pub static OBJECTS: [ObjectDef; Obj::COUNT] = [
            $( ObjectDef {
                obj: Obj::$id,
                addr: $addr,
                // Names and texts serve the register reference and messages: without `docs` (the
                // firmware) they stay out of flash, fields and all.
                #[cfg(feature = "docs")]
                name: $name,
                kind: ObjectDef::kind($ty, $acc, $sto),
                range: &$range,
                default: ($def as i64) as u32,
                #[cfg(feature = "docs")]
                unit: Unit::$unit,
                #[cfg(feature = "docs")]
                doc: concat!($($doc, "\n"),*),
            }, )*
        ];

        // Texts are 4 or 16 bytes (`ObjectDef::kind`).
        const _: () = { $( assert!(!matches!($ty, Str(n) if n != 4 && n != 16)); )* };

        impl Obj {
            /// Every object, in register order.
            pub const ALL: [Obj; Obj::COUNT] = [ $( Obj::$id, )* ];
            /// How many objects there are.
            pub const COUNT: usize = [ $( stringify!($id), )* ].len();
        }
    };
}

impl Obj {
    /// The object's declaration.
    pub fn def(self) -> &'static ObjectDef {
        // `self as usize < COUNT` by construction of the enum; the fallback is never taken.
        OBJECTS.get(self as usize).unwrap_or(&OBJECTS[0])
    }

    /// Whether the object moves with no request changing the drive's settings or motion: the
    /// current command (the standstill current lowers it as time passes) and the not-moving
    /// code (a refused motion command says why in it, as its exception does). What a check that
    /// a refused request changed nothing leaves out.
    pub const fn is_diagnostic(self) -> bool {
        matches!(self, Obj::CurrentCommand | Obj::NotMovingCode)
    }
}

// Declarations are in register order and do not overlap: checked when compiling.
#[allow(clippy::indexing_slicing)]
const _: () = {
    let mut i = 1;
    while i < OBJECTS.len() {
        assert!(OBJECTS[i - 1].end() <= OBJECTS[i].addr as u32);
        assert!(OBJECTS[i].obj as usize == i);
        i += 1;
    }
};

objects! {
    /// Device name, ASCII, zero padded.
    DeviceName @ 0x101A: Str(16), Ro, Const, Any, default 0, None, "device name";
    /// Hardware version, 4 ASCII characters.
    HardwareVersion @ 0x1022: Str(4), Ro, Const, Any, default 0, None, "hardware version";
    /// Software version, 4 ASCII characters (`major.minor` as `VMmm`, e.g. `V001`).
    SoftwareVersion @ 0x1024: Str(4), Ro, Const, Any, default 0, None, "software version";
    /// Group id for group-synchronous starts by broadcast (0x2113, 0x2114). 0: in no group.
    GroupId @ 0x200E: U8, Rw, Rom, Span(0, 127), default 0, None, "group id";
    /// System control. 2 saves every ROM object the master can write (one record, so a power cut
    /// leaves the old set or the new one, never a mix); 3 restores their factory values and saves
    /// them too, so that they survive a restart as §3.11's FSET reset does. Both are refused (04)
    /// while the axis moves (a save keeps the bus side busy for up to a page erase, ~22 ms, when a
    /// stop or a re-target must not wait) or a save is in progress, and 2
    /// on a platform without storage. The reply means the save started: 0x2120 bit 3 shows it
    /// running, bit 4 a failure. 1 (jump to the boot loader) is refused (04): the simulator has
    /// none, and the firmware does not jump. 4 (ours, seed 002's alarm clear) clears the latched
    /// alarms as the motion command 13 does; 5 (ours, seed 003's 0x201D) empties the fault
    /// history 0x213C-0x214F (saved, where the platform saves it; 0x2136 counts on); 0 does
    /// nothing (seed 003's "do not clear"). The manual prints it read-only; its own examples
    /// write it.
    SystemControl @ 0x200F: U8, Cmd, Ram, Set(&[0, 1, 2, 3, 4, 5]), default 0, None, "system control";
    /// Node id (slave address). A write takes effect at the next power-up once saved (0x200F = 2),
    /// so a typo cannot lose the drive; until then the drive answers at the old id. The object
    /// table prints a default of 5; §5.3 and every example use 1.
    NodeId @ 0x2028: U8, Rw, Rom, Span(1, 127), default 1, None, "node id";
    /// Baud rate. A write takes effect at the next power-up once saved (0x200F = 2). 57600 is
    /// accepted beside the manual's list; 51200 is the manual's.
    BaudRate @ 0x202A: U32, Rw, Rom, Set(&crate::units::Baud::SUPPORTED), default 9600, Baud, "baud rate";
    /// Parity of the serial line (our object): 0 none (8N1, the manual's setting), 1 even (8E1,
    /// the Modbus serial-line default), 2 odd. Takes effect after saving and restarting.
    Parity @ 0x2100: U8, Rw, Rom, Span(0, 2), default 0, None, "parity";
    /// S-curve jerk time (our object): how long the acceleration of the native position and
    /// velocity modes takes to build up to its level; jerk = acceleration / jerk time.
    JerkTime @ 0x2101: U16, Rw, Rom, Span(1, 1000), default 50, Millis, "S-curve jerk time";
    /// Standstill current (our object, as seed 002's 0x0213): the phase current in percent of
    /// 0x600D once the motor has stood still for 0x2103. 100: no reduction.
    IdleCurrent @ 0x2102: U8, Rw, Rom, Span(10, 100), default 100, Percent, "standstill current";
    /// Standstill delay (our object, as seed 002's 0x0245): how long the motor stands before the
    /// current drops to 0x2102.
    IdleDelay @ 0x2103: U16, Rw, Rom, Span(1, 32767), default 500, Millis, "standstill delay";
    /// Feedback (our object), read at power-up: 0 open loop; 1 closed loop on the encoder of
    /// 0x6054 (a line count: incremental, ×4; 12: absolute 12-bit single-turn); 2 closed loop on a
    /// 12-bit multi-turn absolute encoder. In closed loop positions count encoder counts (see
    /// `drive_core::servo`).
    Feedback @ 0x2104: U8, Rw, Rom, Span(0, 2), default 0, None, "feedback";
    /// Following error (our object): setpoint − measured position, closed loop; 0 in open loop.
    FollowingError @ 0x2105: S32, Ro, Live, S32_ANY, default 0, Counts, "following error";
    /// Sensorless stall detection in open loop (our object): 1 on, as §5.5.20-21 have it (the
    /// detection always runs; 0x6043 says whether a stall stops the motor); 0 turns it off for a
    /// motor whose resistance and inductance (0x2108, 0x2109) are not known.
    StallDetect @ 0x2107: U8, Rw, Rom, Span(0, 1), default 1, None, "stall detection";
    /// Motor winding resistance (our object), for the back-EMF estimate of the stall detection
    /// and the current loop's model; with 0x210B = 1 the power-up auto-tune's measurement (the
    /// mean of both windings).
    MotorResistance @ 0x2108: U16, Rw, Rom, Span(10, 60_000), default 1400, MilliOhms, "motor resistance";
    /// Motor winding inductance (our object), for the back-EMF estimate of the stall detection
    /// and the current loop's model; with 0x210B = 1 the power-up auto-tune's measurement.
    MotorInductance @ 0x2109: U16, Rw, Rom, Span(10, 60_000), default 3000, MicroHenries, "motor inductance";
    /// Stall detection minimum speed (our object): below this commanded speed (full steps a
    /// second) the back-EMF is too small to tell a stall, and nothing is detected.
    StallMinSpeed @ 0x210A: U16, Rw, Rom, Span(1, 10_000), default 60, None, "stall minimum speed";
    /// The current loop's power-up auto-tune (our object, seed 003's 0x2007), read at power-up,
    /// with the drive's own power stage (the G474 board's bridges, the simulator's `--power-stage
    /// bridges`): 1 measures
    /// both windings' R and L with voltage steps (about a second at the phase current 0x600D,
    /// one winding then the other, before the drive answers) into 0x2108 and 0x2109, and sets
    /// the loop's gains 0x210C and 0x210D from them; 0 runs the loop on 0x2108, 0x2109, 0x210C
    /// and 0x210D as they are. Where the power stage has no current loop (the simulator's
    /// chopper, the firmware under QEMU) none runs, and 0x210B-0x210D refuse changes as
    /// unsupported; a write of the value an object holds is taken in any state.
    CurrentAutoTune @ 0x210B: U8, Rw, Rom, Span(0, 1), default 1, None, "current loop auto-tune";
    /// The current loop's proportional gain (our object, seed 003's 0x2008), read at power-up:
    /// volts across a winding per ampere of error, at the factory decay (0x6010 scales it). Read
    /// only while 0x210B = 1 (the tune sets it).
    CurrentKp @ 0x210C: U16, Rw, Rom, Span(50, 32_767), default 300, DeciVoltsPerAmp, "current loop KP";
    /// The current loop's integral gain (our object, seed 003's 0x2009), read at power-up: volts
    /// added each PWM period per ampere of error. Read only while 0x210B = 1.
    CurrentKi @ 0x210D: U16, Rw, Rom, Span(10, 2_000), default 30, CentiVoltsPerAmpPeriod, "current loop KI";
    /// The current loop's correction gain (our object, seed 003's 0x200A "Kc"): the share of
    /// what the loop's winding model missed at the last sample that corrects its next prediction
    /// (`drive_core::current::CORRECTION_GAIN`), fixed.
    CurrentKc @ 0x210E: U16, Ro, Const, Any, default 250, PerMille, "current loop Kc";
    /// PVT points stored (modes 1 and 2) or queued in the FIFO (mode 3), our object: what a
    /// streaming master reads to know how many points it may send.
    PvtCount @ 0x2110: U16, Ro, Live, PVT_INDEX, default 0, None, "PVT points stored";
    /// PVT faults (our object), write 1 to clear: bit 0 the FIFO ran dry while the axis moved
    /// (it then decelerated to rest with the ramp of 0x600B).
    PvtFault @ 0x2111: U8, W1c, Live, Bits(0x01), default 0, None, "PVT fault";
    /// PVT push on time (our object): 1 makes completing the time 0x602B..2C push the point, as
    /// 0x6017 = 2 does, so one write of 0x6027..0x602C is one point.
    PvtAutoPush @ 0x2112: U8, Rw, Ram, Span(0, 1), default 0, None, "PVT push on time";
    /// Group start (our object): writing g, usually by broadcast (`00 06 21 13 00 gg`), starts
    /// every drive whose group id 0x200E is g at the same control tick (a board's planning margin
    /// after the frame): the PVT run in PVT mode, the synchronous move (0x6047, 0x6049) in
    /// position mode. Other drives ignore it.
    GroupStart @ 0x2113: U8, Cmd, Ram, Span(1, 127), default 0, None, "group start";
    /// Group stop (our object): writing g makes every drive of group g decelerate to rest, as
    /// 0x6017 = 0 does.
    GroupStop @ 0x2114: U8, Cmd, Ram, Span(1, 127), default 0, None, "group stop";
    /// Storage status (our object), write 1 to clear (bit 3 excepted): bit 0 no saved parameters
    /// at power-up, 1 saved parameters unreadable at power-up (both: factory values in use), 2 FSET
    /// held low at power-up (factory values restored and saved), 3 save in progress, 4 last save
    /// failed (the flash keeps the set saved before it), 5 the saved parameters are of a newer
    /// store version than this firmware reads (a rollback after an update that changed it): with
    /// bit 1, factory values in use, and saves refused (04) so that the store stays for the
    /// firmware that wrote it; FSET, or an update back, ends it.
    StorageStatus @ 0x2120: U8, W1c, Live, Bits(0x3F), default 0, None, "storage status";
    /// Under-voltage threshold (our object): a supply below it latches 0x6000 bit 5, alarm 13.
    /// 10 V by default: seed 000 rates the drive for 12-48 V DC, and a 12 V supply sags under
    /// load; raise it for a higher supply.
    UnderVoltage @ 0x2130: U16, Rw, Rom, Any, default 10_000, MilliVolts, "under-voltage threshold";
    /// Over-voltage threshold (our object): a supply above it latches 0x2135 bit 0, alarm 14
    /// (seed 002 alarms above 60 V).
    OverVoltage @ 0x2131: U16, Rw, Rom, Any, default 60_000, MilliVolts, "over-voltage threshold";
    /// Over-temperature threshold (our object): a driver temperature above it latches 0x6000 bit 0,
    /// alarm 15 (our code: seed 002 files over-temperature under "other").
    OverTemperature @ 0x2132: U8, Rw, Rom, Span(40, 150), default 85, Celsius, "over-temperature threshold";
    /// Over-current threshold (our object): a measured phase current beyond it latches 0x6000 bit 3
    /// (phase A) or 4 (phase B), alarm 10. Above the largest phase current 0x600D accepts.
    OverCurrent @ 0x2133: U16, Rw, Rom, Span(500, 10_000), default 8000, MilliAmps, "over-current threshold";
    /// Alarm code (our object, seed 002's codes): the most severe latched alarm, 0 when none:
    /// 10 over-current, 11 phase loss (coil open), 14 over-voltage, 13 under-voltage, 15
    /// over-temperature, 26 overload, in that order of precedence. It clears with the bits.
    AlarmCode @ 0x2134: U8, Ro, Live, Any, default 0, None, "alarm code";
    /// Drive faults beyond 0x6000 (our object), write 1 to clear: bit 0 over-voltage (alarm 14),
    /// bit 1 overload (alarm 26: a phase current above 1.5 times 0x600D for 2 s), bit 2 position
    /// error (alarm 25: closed loop, a following error beyond 0x605C), bit 3 encoder lost (alarm
    /// 27, ours), bit 4 overspeed (alarm 31, ours: the speed beyond 0x21F6), bit 5 the parameter
    /// store failed (alarm 32, ours), bit 6 the current sensing failed its check (alarm 33,
    /// ours); 0x21F8 says which are detected. Like the bits of 0x6000 they disable the power
    /// stage and refuse moves until cleared.
    DriveFaults @ 0x2135: U8, W1c, Live, Bits(0x7F), default 0, None, "drive faults";
    /// Alarms raised (our object), wrapping, kept in flash with the fault history across power
    /// cycles: a master polls it to see new entries in the fault history.
    AlarmCount @ 0x2136: U16, Ro, Live, Any, default 0, None, "alarm count";
    /// Communication timeout (our object, as seed 004's P□602): 0 off, else the longest time
    /// without a valid frame addressed to this drive (or broadcast), in 100 ms. When it runs out a
    /// moving axis decelerates to rest (0x600B's level; PP/PV: 0x6069), 0x2138 bit 0 is set, and
    /// moves are refused (04) until it is cleared. Counted from power-up and from every such frame.
    CommTimeout @ 0x2137: U16, Rw, Rom, Any, default 0, DeciSeconds, "communication timeout";
    /// Communication status (our object), write 1 to clear: bit 0 the communication timeout
    /// 0x2137 ran out.
    CommStatus @ 0x2138: U8, W1c, Live, Bits(0x01), default 0, None, "communication status";
    /// Fault history entry 0 (our object; 0 newest): bits 31-24 the alarm code, bits 23-0 when it
    /// was raised, in 100 ms since power-up (wraps after 19.4 days). 0: no entry.
    FaultHistory0 @ 0x213C: U32, Ro, Live, Any, default 0, None, "fault history 0";
    /// Fault history entry 1 (our object; 0 newest): bits 31-24 the alarm code, bits 23-0 when it
    /// was raised, in 100 ms since power-up (wraps after 19.4 days). 0: no entry.
    FaultHistory1 @ 0x213E: U32, Ro, Live, Any, default 0, None, "fault history 1";
    /// Fault history entry 2 (our object; 0 newest): bits 31-24 the alarm code, bits 23-0 when it
    /// was raised, in 100 ms since power-up (wraps after 19.4 days). 0: no entry.
    FaultHistory2 @ 0x2140: U32, Ro, Live, Any, default 0, None, "fault history 2";
    /// Fault history entry 3 (our object; 0 newest): bits 31-24 the alarm code, bits 23-0 when it
    /// was raised, in 100 ms since power-up (wraps after 19.4 days). 0: no entry.
    FaultHistory3 @ 0x2142: U32, Ro, Live, Any, default 0, None, "fault history 3";
    /// Fault history entry 4 (our object; 0 newest): bits 31-24 the alarm code, bits 23-0 when it
    /// was raised, in 100 ms since power-up (wraps after 19.4 days). 0: no entry.
    FaultHistory4 @ 0x2144: U32, Ro, Live, Any, default 0, None, "fault history 4";
    /// Fault history entry 5 (our object; 0 newest): bits 31-24 the alarm code, bits 23-0 when it
    /// was raised, in 100 ms since power-up (wraps after 19.4 days). 0: no entry.
    FaultHistory5 @ 0x2146: U32, Ro, Live, Any, default 0, None, "fault history 5";
    /// Fault history entry 6 (our object; 0 newest): bits 31-24 the alarm code, bits 23-0 when it
    /// was raised, in 100 ms since power-up (wraps after 19.4 days). 0: no entry.
    FaultHistory6 @ 0x2148: U32, Ro, Live, Any, default 0, None, "fault history 6";
    /// Fault history entry 7 (our object; 0 newest): bits 31-24 the alarm code, bits 23-0 when it
    /// was raised, in 100 ms since power-up (wraps after 19.4 days). 0: no entry.
    FaultHistory7 @ 0x214A: U32, Ro, Live, Any, default 0, None, "fault history 7";
    /// Fault history entry 8 (our object; 0 newest): bits 31-24 the alarm code, bits 23-0 when it
    /// was raised, in 100 ms since power-up (wraps after 19.4 days). 0: no entry.
    FaultHistory8 @ 0x214C: U32, Ro, Live, Any, default 0, None, "fault history 8";
    /// Fault history entry 9 (our object; 0 newest): bits 31-24 the alarm code, bits 23-0 when it
    /// was raised, in 100 ms since power-up (wraps after 19.4 days). 0: no entry.
    FaultHistory9 @ 0x214E: U32, Ro, Live, Any, default 0, None, "fault history 9";
    /// Step notification output (our object): bits 0-3 a GPIO (1-7 GPIO1-7, 8 GPIO8; 0 none)
    /// that goes high for bits 8-15 ms when a bit of 0x6061 sets. The pin must be an output
    /// (0x602E); its level in 0x6031 is the master's outside the pulse.
    NotifyOutput @ 0x2150: U16, Rw, Rom, Bits(0xFF0F), default 0, None, "step notify output";
    /// Coil output function (our object): 0 brake, 1 general output. As a brake (§5.14) 0x6038 is
    /// the release duty while the power stage is on, and 0 (applied) when it is off, on a fault,
    /// or in power loss below 0x6084. As a general output (§3.10: valve, magnet, DC load) 0x6038
    /// is the duty whatever the motor does, cut to 0 while a fault is latched.
    CoilMode @ 0x2151: U8, Rw, Rom, Span(0, 1), default 0, None, "coil output function";
    /// Homing method (our object; CiA 402's numbers as a signed 16-bit value): 17/18 on the
    /// negative/positive limit switch, 19/20 a home switch actuated above home, 21/22 one
    /// actuated below, 1-6 the same then the first index pulse, 33/34 the index alone, 35/37
    /// the present position, -1/-2 a hard stop found by the stall detection (positive,
    /// negative, as Maxon numbers its vendor methods), -3 to -10 JMC's methods 1-8 (a limit
    /// or the home switch reached, reversing at a limit, at one speed or approached again at
    /// the creep speed). See `drive_core::state::homing` for each one's moves; 7-14 and 23-30
    /// are refused.
    HomingMethod @ 0x2160: U16, Rw, Rom, Set(&HOMING_METHODS), default 35, None, "homing method";
    /// Homing command (our object): 1 starts (refused, 04, while moving or when the method's
    /// switch has no input in 0x216C, or when a hard stop cannot be felt: the stall detection
    /// off or the creep speed below 0x210A), 0 stops it at 0x2167. Moves are refused meanwhile as
    /// ever (a new motion command interrupts it).
    HomingControl @ 0x2161: U8, Cmd, Ram, Span(0, 1), default 0, None, "homing command";
    /// Homing result (our object): 0 not homed since power-up, 1 running, 2 homed (the position
    /// where the home was caught is 0x2169 now), 3 the timeout 0x216B ran out, 4 interrupted
    /// (0x2161 = 0, another motion command, a stop, an EXT stop, a fault).
    HomingResult @ 0x2162: U8, Ro, Live, Span(0, 4), default 0, None, "homing result";
    /// Homing search speed (our object): the searches for a switch.
    HomingSearchSpeed @ 0x2163: U32, Rw, Rom, Span(1, 200_000), default 3200, Pps, "homing search speed";
    /// Homing creep speed (our object): every edge, index and hard stop is found at it; the
    /// position is caught within one control tick of travel (creep / 20 000 microsteps).
    HomingCreepSpeed @ 0x2165: U32, Rw, Rom, Span(1, 200_000), default 800, Pps, "homing creep speed";
    /// Homing acceleration and deceleration (our object).
    HomingAccel @ 0x2167: U32, Rw, Rom, Span(151, i32::MAX), default 32_000, Pps2, "homing acceleration";
    /// Homing offset (our object): the position the home gets.
    HomingOffset @ 0x2169: S32, Rw, Rom, S32_ANY, default 0, Steps, "homing offset";
    /// Homing timeout (our object): the homing gives up after this long (0: never).
    HomingTimeout @ 0x216B: U16, Rw, Rom, Any, default 600, DeciSeconds, "homing timeout";
    /// Homing inputs (our object): bits 0-3 the home switch, 4-7 the negative limit switch, 8-11
    /// the positive limit switch: 0 none, 1-3 EXT1-3, 4-10 GPIO1-7, 11 GPIO8. An EXT input's
    /// external stop is suspended while a homing searches its switch.
    HomingInputs @ 0x216C: U16, Rw, Rom, Bits(0x0FFF), default 0x0001, None, "homing inputs";
    /// Homing input polarity (our object): bit 0 the home switch, 1 the negative limit, 2 the
    /// positive limit, is actuated at a high level (1) or a low one (0).
    HomingPolarity @ 0x216D: U8, Rw, Rom, Bits(0x07), default 0, None, "homing polarity";
    /// Homing zero speed (our object; JMC's 0x609B): 0 the axis stays at the home; else, the
    /// position declared, it moves to position 0 at this speed (0x2169 away from the home) and
    /// the homing ends there.
    HomingZeroSpeed @ 0x216E: U32, Rw, Rom, Span(0, 200_000), default 0, Pps, "homing zero speed";
    /// Analog speed (our object; §3.9's analog speed control): 1 makes the analog input set the
    /// speed in the velocity mode (0x6007 = 1): 0 at the start code 0x6078 and below, 0x2171 at
    /// code 4095, averaged over 0x6079 (see `drive_core::state::analog`).
    AnalogSpeedEnable @ 0x2170: U8, Rw, Rom, Span(0, 1), default 0, None, "analog speed enable";
    /// Analog speed at code 4095 (our object); its sign is the direction.
    AnalogSpeedFull @ 0x2171: S32, Rw, Rom, Span(-200_000, 200_000), default 3200, Pps, "analog full-scale speed";
    /// Analog speed dead band (our object): a new speed is taken only when it differs from the
    /// one in force by more than this.
    AnalogSpeedDeadband @ 0x2173: U16, Rw, Rom, Any, default 50, Pps, "analog speed dead band";
    /// Device controlword (our object; CiA 402's 0x6040, the compatibility maps' controlword):
    /// bits 0-3 and 7 command the power state machine of `drive_core::power` (shutdown 0x06,
    /// switch on 0x07, enable operation 0x0F, disable voltage, quick stop, fault reset on bit
    /// 7's rising edge); in operation enabled bits 4-6, 8 and 9 act as 0x6070's in the profile
    /// modes, and in the homing mode (0x6007 = 6) bit 4's rising edge starts the homing of
    /// 0x2160 and bit 8 halts it.
    DeviceControl @ 0x2180: U16, Rw, Ram, Any, default 0, None, "device controlword";
    /// Device statusword (our object; CiA 402's 0x6041): bits 0-6 the power state (see
    /// `drive_core::power`), 7 warning (the supply below the free-wheel voltage), 8 halted, 9
    /// moving, 10 target reached (PP: at rest on the target; PV: at the speed; homing: ended),
    /// 11 the home switch, 12 a new set-point can be taken (PP: 0x6071's acknowledge
    /// inverted, as seed 001 has it), speed 0 (PV), homed (homing), 13
    /// following error (PP, closed loop) or homing error, 14 the negative limit switch, 15 the
    /// positive one (switches as 0x216C assigns them).
    DeviceStatus @ 0x2181: U16, Ro, Live, Any, default 0, None, "device statusword";
    /// Quick stop option (our object; CiA 402's 0x605A): 0 the power stage off at once, 1 stop
    /// at the profile's deceleration (0x6069) and 2 at 0x2183, both then to switch on disabled;
    /// 5 and 6 the same, staying in quick stop active; 0xFFFF (-1) stop at once and stay
    /// energised, then to switch on disabled.
    QuickStopOption @ 0x2182: U16, Rw, Rom, Set(&crate::power::QuickStopOption::RAW), default 2, None, "quick stop option";
    /// Quick stop deceleration (our object; CiA 402's 0x6085).
    QuickStopDecel @ 0x2183: U32, Rw, Rom, Span(151, i32::MAX), default 320_000, Pps2, "quick stop deceleration";
    /// Error register (our object; CiA 301's 0x1001): bit 0 any fault, 1 current (over-current,
    /// overload), 2 voltage (under- or over-voltage), 3 temperature, 4 communication (the
    /// timeout of 0x2137), 5 position error (closed loop), 7 a coil open. Read only.
    ErrorRegister @ 0x2185: U8, Ro, Live, Any, default 0, None, "error register";
    /// Register map (our object): which vendor's registers the drive answers to, from the next
    /// power-up once saved (0x200F = 2): 0 native (seed 000), 1 JMC (seed 001), 2 DS-CLS9
    /// (seed 002), 3 EC-57 (seed 003), 4 servo (seed 004). Every map has it at this address (the EC-57 map in its
    /// window, index 0x2190 sub-index 0xFF), so a master can always switch back. A map the
    /// platform does not carry is refused (04).
    RegisterMap @ 0x2190: U8, Rw, Rom, Span(0, 4), default 0, None, "register map";
    /// Word order of the compatibility maps that make it a setting (our object; JMC's 0x6000):
    /// 0 high word first, 1 low word first.
    MapWordOrder @ 0x2191: U8, Rw, Rom, Span(0, 1), default 0, None, "map word order";
    /// Framing of the serial line (our object; seed 004's P□600 chooses it): 0 RTU, 1 Modbus
    /// ASCII (`:`, hex, LRC, CR LF). Takes effect after saving and restarting, as the baud rate.
    LineFraming @ 0x2192: U8, Rw, Rom, Span(0, 1), default 0, None, "line framing";
    /// Communication IO (our object; seed 004's 0451h): signals a master sets, each acting as the
    /// same signal from an input would while no input carries its function: bit 0 servo on (the
    /// power state machine, as 0x6011), 2 positive and 3 negative overtravel (as limit switches),
    /// 4 alarm reset (rising edge: as 0x200F = 4), 5 clear (rising edge, at rest: the position
    /// error cleared, the commanded position the actual one), 9-11 the position data group
    /// (POS0-2), 13 start the selected group (rising edge), 14 step to the next group (rising
    /// edge), 15 start homing (rising edge). Bits 1 (P-CON), 6-8 (torque limits, gain select)
    /// and 12 (POS-REF: the home switch must come from an input, which the tick watches) are
    /// refused. Not saved.
    CommInputs @ 0x2193: U16, Rw, Ram, Bits(0xEE3D), default 0, None, "communication IO";
    /// Speed jog (our object; seed 004's 0528h): bit 15 energises the motor for the jog (off
    /// stops and de-energises it), bit 0 jogs positive, bit 1 negative at 0x21A5 while set (both
    /// or neither: decelerate to rest); bits 0-1 need bit 15.
    SpeedJog @ 0x2194: U16, Rw, Ram, Bits(0x8003), default 0, None, "speed jog";
    /// Position jog (our object; seed 004's 0529h): bit 15 energises the motor for the jog (off
    /// de-energises it once at rest), a rising bit 0 moves 0x2196 positive, bit 1 negative, at
    /// 0x21A5; bits 0-1 need bit 15.
    PositionJog @ 0x2195: U16, Rw, Ram, Bits(0x8003), default 0, None, "position jog";
    /// The distance a position jog moves (our object).
    JogDistance @ 0x2196: U32, Rw, Rom, Span(1, 100_000_000), default 200, Steps, "jog distance";
    /// The position data group running (our object; seed 004's 05F0h), 0-31; 0xFFFF none.
    GroupRunning @ 0x2198: U16, Ro, Live, Any, default 0xFFFF, None, "running data group";
    /// The group the chain goes on with (our object; seed 004's 05F1h), 0-31; 0xFFFF none.
    GroupNext @ 0x2199: U16, Ro, Live, Any, default 0xFFFF, None, "next data group";
    /// Where the group selection comes from (our object; seed 004's 05F4h): 0 the communication
    /// IO's POS0-2 (task), 1 inputs with the segment-select functions 25-27 (external).
    GroupSource @ 0x219A: U8, Ro, Live, Span(0, 1), default 0, None, "data group source";
    /// Numerator of the position data groups' electronic gear (our object; seed 004's 05F8h): a
    /// group's position unit is numerator / denominator microsteps.
    GearNumerator @ 0x219B: U16, Rw, Rom, Span(1, 65_535), default 1, None, "group gear numerator";
    /// Denominator of the position data groups' electronic gear (our object; seed 004's 05F9h).
    GearDenominator @ 0x219C: U16, Rw, Rom, Span(1, 65_535), default 1, None, "group gear denominator";
    /// Teach position (our object; seed 004's 05FDh/05FEh): a write names the place the axis
    /// stands on (as the position 0x600E, refused while moving); reads the last one written.
    TeachPosition @ 0x219D: S32, Rw, Ram, S32_ANY, default 0, Steps, "teach position";
    /// Restart (our object; seed 004's 0541h): 1 restarts the drive as a power cycle would, once
    /// the reply is sent; refused while moving or saving.
    Restart @ 0x219F: U8, Cmd, Ram, Span(1, 1), default 0, None, "restart";
    /// Motion command (our object; seed 002's control command 0323), acting on its write in any
    /// work mode (in PVT mode (0x6007 = 2) only 6 and 7, which end the run; the others 04): 0
    /// nothing; 1 absolute run to 0x21A1 at 0x21B5's speed (re-targets a
    /// running absolute run); 2 relative run by 0x21A1 (the sign the direction; refused (04)
    /// while moving); 3 run at 0x21A3 (its sign the direction; a write to 0x21A3 during the run
    /// changes the speed); 4 / 5 jog positive / negative at 0x21A5 until a stop; 6 stop at the
    /// deceleration 0x6069; 7 emergency stop at 0x2183; 8 set the position to 0x21A7 (refused
    /// (04) while moving); 12 the homing of 0x2160 (as 0x2161 = 1); 13 clear the alarms (0x6000,
    /// 0x2135, 0x2138, 0x6001's external stop and stall), leaving the enable as it is. Runs and
    /// jogs ramp with 0x6067, 0x6069, 0x606B and 0x606D, and stop at an enabled soft limit
    /// (0x21AD). 14-18 act on the multi-segment program (`state::program`) of a map that has a
    /// program window (seed 002's; the native map has none and refuses them, 04): 14
    /// check it (0x21CE), 15 save it with the parameters (as 0x200F = 2), 16 start the selected
    /// segment or resume a paused one, 17 pause, 18 end; while a program runs the other motion
    /// commands but 6 and 7 (which end it) are refused (04). A value the drive does not do is
    /// refused (03).
    MotionCommand @ 0x21A0: U16, Cmd, Ram, Set(&crate::modes::Command::RAW), default 0, None, "motion command";
    /// Command target (our object; seed 002's 0313): the position of an absolute run, the
    /// distance of a relative one (0x21A0).
    CommandTarget @ 0x21A1: S32, Rw, Ram, S32_ANY, default 0, Steps, "command target";
    /// Run velocity (our object; seed 002's 0307): the speed of the motion command's run (3),
    /// its sign the direction.
    CommandVelocity @ 0x21A3: S32, Rw, Rom, Magnitude(150, 300_000), default 2000, Pps, "run velocity";
    /// Jog speed (our object; seed 002's 0308): the speed of the motion command's jogs (4, 5).
    JogSpeed @ 0x21A5: U32, Rw, Rom, Span(150, 300_000), default 2000, Pps, "jog speed";
    /// Position preset (our object; seed 002's 0321): the position the motion command 8 sets.
    PositionPreset @ 0x21A7: S32, Rw, Ram, S32_ANY, default 0, Steps, "position preset";
    /// Positive soft limit (our object; seed 002's 0317): with 0x21AD bit 0, no motion command
    /// (0x21A0) goes beyond it: a target beyond it stops on it, a run or jog towards it becomes a
    /// move to it. Homing and the native map's own moves are not bound by it.
    SoftLimitPositive @ 0x21A9: S32, Rw, Rom, Span(-2_000_000_000, 2_000_000_000), default 2_000_000_000, Steps, "positive soft limit";
    /// Negative soft limit (our object; seed 002's 0319): as 0x21A9, with 0x21AD bit 1.
    SoftLimitNegative @ 0x21AB: S32, Rw, Rom, Span(-2_000_000_000, 2_000_000_000), default -2_000_000_000, Steps, "negative soft limit";
    /// Soft limits (our object; seed 002's 0324): bit 0 the positive limit 0x21A9 on, bit 1 the
    /// negative one 0x21AB.
    SoftLimits @ 0x21AD: U8, Rw, Rom, Bits(0x03), default 0, None, "soft limits";
    /// Run state (our object; seed 002's 0109): 1 the power stage off (disabled, freed or a
    /// fault), 2 energised and standing, 3 moving.
    RunState @ 0x21AE: U8, Ro, Live, Span(1, 3), default 1, None, "run state";
    /// Supply voltage (our object; seed 002's 0101), as last measured; 0 where the platform
    /// does not measure it.
    SupplyVoltage @ 0x21AF: U16, Ro, Live, Any, default 0, MilliVolts, "supply voltage";
    /// Motor current (our object; seed 002's 0100): the larger phase current's magnitude, as
    /// last measured; 0 where the platform does not measure it.
    MotorCurrent @ 0x21B0: U16, Ro, Live, Any, default 0, MilliAmps, "motor current";
    /// Target position (our object; seed 002's 0117): where the running motion heads, or the
    /// position when the axis stands or runs at a speed.
    TargetPosition @ 0x21B1: S32, Ro, Live, S32_ANY, default 0, Steps, "target position";
    /// Hardware revision (our object; seed 002's 0110), major × 100 + minor.
    HardwareRevision @ 0x21B3: U16, Ro, Const, Any, default 100, None, "hardware revision";
    /// Software revision (our object; seed 002's 0111): the firmware's version, major × 100 +
    /// minor.
    SoftwareRevision @ 0x21B4: U16, Ro, Const, Any, default crate::ident::SOFTWARE_REVISION, None, "software revision";
    /// Run speed (our object; seed 002's 0306): the speed of the motion command's absolute and
    /// relative runs (0x21A0 = 1, 2).
    CommandSpeed @ 0x21B5: U32, Rw, Rom, Span(150, 300_000), default 2000, Pps, "run speed";
    /// Pulse input format (our object; seed 002's 0244 and 0106): 1 pulse and direction (DIR
    /// high counts down), 2 double pulse (CW up, CCW down), 3 an encoder's quadrature A/B, every
    /// edge a count. What the pulse following of work mode 3 counts; takes effect at once.
    PulseFormat @ 0x21B7: U8, Rw, Rom, Span(1, 3), default 1, None, "pulse input format";
    /// Pulse input filter (our object; seed 002's 0234): 1-15, the input timer's filter (the
    /// STM32's ICxF at 170 MHz): a level must hold 2, 4, 8, 12, 16, 24, 32, 48, 64, 80, 96, 128,
    /// 160, 192 or 256 timer clocks (12 ns to 1.5 µs) to count. Higher filters reject more noise
    /// and cap the pulse rate lower (at 15: 330 kpps of 50 % pulses).
    PulseFilter @ 0x21B8: U8, Rw, Rom, Span(1, 15), default 1, None, "pulse input filter";
    /// Pulse following at power-up (our object; seed 002's 0296, "0 external, 1 internal
    /// pulses"): 1 the drive powers up in work mode 3, following the pulse input; 0 in mode 0,
    /// commanded over the bus. Read at power-up only: save it and restart, as seed 002 says.
    PulseAtPowerUp @ 0x21B9: U8, Rw, Rom, Span(0, 1), default 0, None, "pulse following at power-up";
    /// IN1 function (our object; seed 002's 0400; IN2-IN7 are 0x21BB-0x21C0, its 0401-0406):
    /// what the input does when it turns active (at 0x21C1's level, or its pseudo-input 0x21C2
    /// set): 0 nothing; 1-8, 12 and 13 the motion command of that number (0x21A0); 9 / 10 the
    /// positive / negative limit switch: a motion heading into an active one stops at the stop
    /// deceleration and a command towards it is refused (04); 11 the home switch of the homing
    /// (9 and 10 its limits too), over 0x216C; 20 enable: 0x6011 takes the input's level when
    /// it changes; 14-19 the program commands of 0x21A0 (19: the next position data group, seed
    /// 004's POS-STEP); 21 / 22 touch probe 1 / 2: the control
    /// tick captures the position at the input's activation (0x21DB-0x21DF; a pseudo-input
    /// captures nothing); 25-29 bits 0-4 of the program segment a start runs (0x21CD; seed 004's
    /// POS0-2 the data group's bits 0-2). IN1-IN3
    /// are EXT1-EXT3, IN4-IN7 GPIO1-GPIO4.
    InputFunction1 @ 0x21BA: U8, Rw, Rom, Set(INPUT_FUNCTIONS), default 0, None, "IN1 function";
    /// IN2 function (our object; seed 002's 0401): as 0x21BA.
    InputFunction2 @ 0x21BB: U8, Rw, Rom, Set(INPUT_FUNCTIONS), default 0, None, "IN2 function";
    /// IN3 function (our object; seed 002's 0402): as 0x21BA.
    InputFunction3 @ 0x21BC: U8, Rw, Rom, Set(INPUT_FUNCTIONS), default 0, None, "IN3 function";
    /// IN4 function (our object; seed 002's 0403): as 0x21BA.
    InputFunction4 @ 0x21BD: U8, Rw, Rom, Set(INPUT_FUNCTIONS), default 0, None, "IN4 function";
    /// IN5 function (our object; seed 002's 0404): as 0x21BA.
    InputFunction5 @ 0x21BE: U8, Rw, Rom, Set(INPUT_FUNCTIONS), default 0, None, "IN5 function";
    /// IN6 function (our object; seed 002's 0405): as 0x21BA.
    InputFunction6 @ 0x21BF: U8, Rw, Rom, Set(INPUT_FUNCTIONS), default 0, None, "IN6 function";
    /// IN7 function (our object; seed 002's 0406): as 0x21BA.
    InputFunction7 @ 0x21C0: U8, Rw, Rom, Set(INPUT_FUNCTIONS), default 0, None, "IN7 function";
    /// Input logic (our object; seed 002's 0429): bit k set, IN k+1 is active low.
    InputLogic @ 0x21C1: U8, Rw, Rom, Bits(0x7F), default 0, None, "input logic";
    /// Pseudo-inputs (our object; seed 002's 0410-0416, a bit each): bit k set acts as IN k+1
    /// turning active (its function at once; an enable input's level while set).
    PseudoInputs @ 0x21C2: U8, Rw, Ram, Bits(0x7F), default 0, None, "pseudo inputs";
    /// OUT1 function (our object; seed 002's 0420, 100 more; OUT2-OUT4 are 0x21C4-0x21C6): 0 none
    /// (the pin is GPIO5 as 0x602E/0x602F/0x6031 set it), 1 general (on while 0x21C7's bit is
    /// set), 2 alarm (on while no alarm is latched), 3 in position (on while the axis stands on
    /// its target, within 0x21C9 in closed loop), 4 motor free (on while the power stage is off),
    /// 5 ready (on while it drives the motor), 6 speed coincidence (seed 004's /V-CMP: on while the
    /// speed is within 0x21F2 of the commanded one, in a position move while in position). An output with a function is a push-pull output,
    /// high when on unless 0x21C8 inverts it. OUT1-OUT4 are GPIO5-GPIO8.
    OutputFunction1 @ 0x21C3: U8, Rw, Rom, Span(0, 6), default 0, None, "OUT1 function";
    /// OUT2 function (our object; seed 002's 0421): as 0x21C3, on GPIO6.
    OutputFunction2 @ 0x21C4: U8, Rw, Rom, Span(0, 6), default 0, None, "OUT2 function";
    /// OUT3 function (our object; seed 002's 0422): as 0x21C3, on GPIO7.
    OutputFunction3 @ 0x21C5: U8, Rw, Rom, Span(0, 6), default 0, None, "OUT3 function";
    /// OUT4 function (our object; seed 002's 0423): as 0x21C3, on GPIO8.
    OutputFunction4 @ 0x21C6: U8, Rw, Rom, Span(0, 6), default 0, None, "OUT4 function";
    /// General outputs (our object; seed 002's 0428): bit k turns OUT k+1 on if its function is 1.
    GeneralOutputs @ 0x21C7: U8, Rw, Ram, Bits(0x0F), default 0, None, "general outputs";
    /// Output logic (our object; seed 002's 0430): bit k set, OUT k+1 is low when on.
    OutputLogic @ 0x21C8: U8, Rw, Rom, Bits(0x0F), default 0, None, "output logic";
    /// In-position window (our object; seed 002's 0247): in closed loop the in-position output
    /// needs the encoder within this many counts of the target; in open loop standing on it.
    InPositionWindow @ 0x21C9: U16, Rw, Rom, Span(0, 1000), default 0, None, "in-position window";
    /// Motor direction (our object; seed 002's 0201): 1 turns the motor the other way for the same
    /// commands, positions and pulses (the power stage drives phase B inverted and reads the
    /// encoder and phase B mirrored). From the next power-up (save first): switched under a
    /// standing, energised motor it would jump by up to two full steps.
    MotorDirection @ 0x21CA: U8, Rw, Rom, Span(0, 1), default 0, None, "motor direction";
    /// Program segments (our object; seed 002's 0327): how many segments the multi-segment
    /// program has, 1-32; a check (0x21A0 = 14) and a start check all of them.
    ProgramSegments @ 0x21CB: U8, Rw, Rom, Span(1, 32), default 1, None, "program segments";
    /// Program segment select (our object; seed 002's 0328): a start (0x21A0 = 16) runs segment
    /// this + 1, unless an input selects one (functions 25-29 of 0x21BA-0x21C0).
    ProgramSelect @ 0x21CC: U8, Rw, Rom, Span(0, 31), default 0, None, "program segment select";
    /// The segment the inputs select (our object; seed 002's 0174): 1 + the bits of the inputs
    /// with functions 25-29 (bit 0-4) that are active, 0 when no input has such a function.
    ProgramInputSegment @ 0x21CD: U8, Ro, Live, Span(0, 32), default 0, None, "input-selected segment";
    /// The segment in error (our object; seed 002's 0176): the first segment the last check
    /// (0x21A0 = 14) or refused start (16) found in error, 1-32; 0 none.
    ProgramErrorSegment @ 0x21CE: U8, Ro, Live, Span(0, 32), default 0, None, "program error segment";
    /// The running segment (our object; seed 002's 0178): 1-32 while a program runs or is
    /// paused, else 0.
    ProgramRunning @ 0x21CF: U8, Ro, Live, Span(0, 32), default 0, None, "running segment";
    /// Position error limit (our object; seed 002's 0258), encoder counts (lines × 4 a
    /// revolution): in closed loop a following error beyond it is the position error alarm (25),
    /// as beyond 0x605C, which it replaces while it is not 0 (converted at the resolution in
    /// force, rounded to the nearest microstep, one at least).
    PositionErrorLimit @ 0x21D0: U16, Rw, Rom, Span(0, 30_000), default 0, None, "position error limit";
    /// Address source (our object; seed 003's 0x2001), read at power-up under the EC-57 map: 0
    /// the serial port's fixed address 1 (the manual's: an EC-57's switches address its
    /// fieldbus, not its serial port), 1 and 2 the node id 0x2028 (its register, kept in the
    /// drive's flash: the manual's 2150h and EEPROM). The other maps answer at 0x2028.
    AddressSource @ 0x21D1: U8, Rw, Rom, Span(0, 2), default 0, None, "address source";
    /// CRC error answer (our object, the EC-57 map's): 0 a frame whose CRC is wrong is dropped
    /// (seed 003 §1.3.4's text, and the Modbus serial line); 1 it is answered with exception 01
    /// (the manual's example, `01 83 01`) if it began with this drive's address. The other maps
    /// drop it whatever this holds.
    CrcErrorReply @ 0x21D2: U8, Rw, Rom, Span(0, 1), default 0, None, "CRC error answer";
    /// Input states (our object; seed 003's 0x2014): bit k set, IN k+1 is active (at 0x21C1's
    /// level, or its pseudo-input 0x21C2 set).
    InputStates @ 0x21D3: U8, Ro, Live, Bits(0x7F), default 0, None, "input states";
    /// Position commanded (our object; seed 003's 0x2010/0x2011): the whole microsteps (encoder
    /// counts in closed loop) the setpoint has moved since power-up or the last clear, signed
    /// (two's complement) and wrapping; a position preset or a homing's new zero is no motion.
    /// Writing 0 clears it.
    CommandCount @ 0x21D4: U32, Rw, Live, Span(0, 0), default 0, Steps, "position commanded";
    /// Position error angle (our object; seed 003's 0x200F), degrees of the motor shaft: in
    /// closed loop a following error beyond it is the position error alarm (25); while not 0 it
    /// replaces 0x21D0 and 0x605C (converted at the resolution in force, a microstep at least;
    /// 0x21D7 = 0 turns the alarm off).
    PositionErrorAngle @ 0x21D6: U16, Rw, Rom, Span(0, 360), default 0, Degrees, "position error angle";
    /// Position error alarm (our object; seed 003's 0x200E): 0 turns the closed loop's position
    /// error alarm off (the loop still follows; a stall bit is never set by it), 1 on.
    PositionErrorAlarm @ 0x21D7: U8, Rw, Rom, Span(0, 1), default 1, None, "position error alarm";
    /// Power-up jog (our object; seed 003's 0x2013): 1 turns the motor 30° forward, then 15°
    /// back, once after power-up, at the jog speed 0x21A5 and the PP ramps (0x6067, 0x6069),
    /// then it stands; a motion command, a stop or an alarm before it is done ends it, and a
    /// drive that cannot move at power-up (power stage off, an alarm) does not jog.
    PowerUpJog @ 0x21D8: U8, Rw, Rom, Span(0, 1), default 0, None, "power-up jog";
    /// In-position source (our object; seed 003's 0x2020): 1 the in-position output (0x21C3
    /// function 3) is on while the axis stands on its target within 0x21C9 encoder counts in
    /// closed loop, the drive's own measure; 0 once the plan has ended, whatever the encoder
    /// says.
    InPositionSource @ 0x21D9: U8, Rw, Rom, Span(0, 1), default 1, None, "in-position source";
    /// Hold when disabled (our object; seed 003's 0x2006): 1 keeps the motor held where it
    /// stands, at the standstill current (0x2102 of 0x600D), while the power stage is disabled
    /// (0x6011 = 0, the power state machine's disabled states); a fault or a power loss frees it
    /// all the same. 0 frees it.
    DisabledHold @ 0x21DA: U8, Rw, Rom, Span(0, 1), default 0, None, "hold when disabled";
    /// Touch probe 1's position (our object; seed 003's probe function of 0x2022): where the
    /// axis was at the tick that saw the input with function 21 turn active, in the position's
    /// unit (the encoder's, counts, in closed loop; the setpoint's microsteps in open loop).
    ProbePosition1 @ 0x21DB: S32, Ro, Live, S32_ANY, default 0, Steps, "touch probe 1 position";
    /// Touch probe 2's position (our object): as 0x21DB, for the input with function 22.
    ProbePosition2 @ 0x21DD: S32, Ro, Live, S32_ANY, default 0, Steps, "touch probe 2 position";
    /// Touch probe status (our object), write 1 to clear: bit 0 probe 1 captured (0x21DB holds
    /// it), bit 1 probe 2. A probe captures at its first activation after its bit was cleared
    /// (armed from power-up); later ones leave the capture as it is.
    ProbeStatus @ 0x21DF: U8, W1c, Live, Bits(0x03), default 0, None, "touch probe status";
    /// Soft start time (our object; seed 003's 0x200B): with 0x21E1 on, the phase current rises
    /// from 0 to its setting over this long each time the power stage is energised (power-up,
    /// enable, a fault cleared), so that the rotor eases onto its step instead of jumping to it.
    /// (The manual's factory value 0 is outside its own range, 10-3000: 100 ms here.)
    SoftStartTime @ 0x21E0: U16, Rw, Rom, Span(10, 3000), default 100, Millis, "soft start time";
    /// Soft start (our object; seed 003's 0x200C): 1 ramps the current up over 0x21E0 when the
    /// stage is energised; 0 energises it at once.
    SoftStart @ 0x21E1: U8, Rw, Rom, Span(0, 1), default 0, None, "soft start";
    /// Electrical angle (our object): the rotor's place in its electrical cycle (4 full steps), by
    /// the commanded microstep.
    ElectricalAngle @ 0x21E2: U16, Ro, Live, Span(0, 359), default 0, Degrees, "electrical angle";
    /// Pulse input speed (our object): the pulse following's rate, microsteps a second; 0 when
    /// not following.
    PulseRate @ 0x21E3: S32, Ro, Live, S32_ANY, default 0, Pps, "pulse input speed";
    /// Analog speed command (our object): the speed the analog input asks for (0x2170-0x2173),
    /// 0 while 0x2170 is off.
    AnalogSpeed @ 0x21E5: S32, Ro, Live, S32_ANY, default 0, Pps, "analog speed command";
    /// Current command (our object): the phase current the drive sets now, percent of 0x600D
    /// (the standstill current included); 0 de-energised.
    CurrentCommand @ 0x21E7: U16, Ro, Live, Any, default 0, Percent, "current command";
    /// Output states (our object): bit k OUT k+1 on (its function active), before 0x21C8.
    OutputStates @ 0x21E8: U8, Ro, Live, Bits(0x0F), default 0, None, "output states";
    /// Encoder signals (our object): bit 0 A, bit 1 B, the quadrature levels of the encoder's
    /// count (0 without an encoder).
    EncoderSignals @ 0x21E9: U8, Ro, Live, Bits(0x03), default 0, None, "encoder signals";
    /// Load (our object): the measured phase current, percent of 0x600D; the overload alarm is
    /// 150 % for 2 s.
    Load @ 0x21EA: U16, Ro, Live, Any, default 0, Percent, "load";
    /// Encoder angle (our object): the place within a revolution by the encoder, microsteps at
    /// the resolution in force (0 without an encoder).
    EncoderAngle @ 0x21EB: U32, Ro, Live, Any, default 0, Steps, "encoder angle";
    /// Encoder turns (our object): whole revolutions by the encoder (0 without one).
    EncoderTurns @ 0x21ED: S32, Ro, Live, S32_ANY, default 0, None, "encoder turns";
    /// Actual position (our object): the commanded position less the following error (the
    /// encoder's place in closed loop; the commanded one in open loop).
    ActualPosition @ 0x21EF: S32, Ro, Live, S32_ANY, default 0, Steps, "actual position";
    /// Serial format (our object; seed 004's P□600), a view of 0x202A, 0x2100 and 0x2192 as two
    /// hexadecimal digits: digit 0 the baud rate (0 4800, 1 9600, 2 19200, 3 38400, 4 57600,
    /// 5 115200; 51200 reads as 6 and is not written so), digit 1 the framing and parity (0 RTU
    /// 8N1, 1 RTU 8E1, 2 RTU 8O1, 3 ASCII 8N1, 4 ASCII 8E1, 5 ASCII 8O1). Takes effect after
    /// saving and restarting, as the three objects.
    SerialFormat @ 0x21F1: U16, Rw, Live, Set(&SERIAL_FORMATS), default 0x01, None, "serial format";
    /// Speed coincidence window (our object; seed 004's P□503): an output with function 6 is on
    /// while the speed is within this much of the commanded one (in a position move: while in
    /// position).
    SpeedWindow @ 0x21F2: U32, Rw, Rom, Span(0, 300_000), default 33, Pps, "speed coincidence window";
    /// Signal inputs 1 (our object; seed 004's P□512), a view of the inputs' functions as four
    /// hexadecimal digits, one a signal: .0 /START-HOME (function 12), .1 /POS-START (16), .2
    /// /POS-STEP (19), .3 /ALM-RST (13); a digit 1-7 is the input IN1-IN7 that carries it, 0
    /// none (the communication IO's bit acts). A write gives each named input that function
    /// (whatever it had) and takes it from every other input; two signals on one input are
    /// refused.
    SignalInputs1 @ 0x21F4: U16, Rw, Live, Bits(0x7777), default 0, None, "signal inputs 1";
    /// Signal inputs 2 (our object; seed 004's P□513), as 0x21F4: .0 /POS0 (function 25), .1
    /// /POS1 (26), .2 /POS2 (27), .3 /SON (the enable, 20).
    SignalInputs2 @ 0x21F5: U16, Rw, Live, Bits(0x7777), default 0, None, "signal inputs 2";
    /// Overspeed limit (our object; seed 003's 0x2012), revolutions of the shaft a minute; 0
    /// off. A motion planned on the bus side whose speed is beyond it is refused (the map's
    /// "no trajectory" code, 04 here) and 0x21F7 reads 30; the speed the motor runs at (the
    /// encoder's in closed loop, the command's in open loop: a PVT segment, the pulse input)
    /// beyond it latches 0x2135 bit 4, the overspeed alarm (31), while 0x21F8 bit 3 detects it.
    /// A stop or a slow-down is never refused.
    OverspeedLimit @ 0x21F6: U16, Rw, Rom, Span(0, 3000), default 0, Rpm, "overspeed limit";
    /// Not-moving code (our object; seed 003's 0x201F): why the last motion command did not
    /// move the motor: 30 its speed is beyond the overspeed limit 0x21F6, 23 the work mode or
    /// state in force does not take it (another mode's command, a speed of 0, a PVT run's
    /// points missing); 0 once a motion command is taken.
    NotMovingCode @ 0x21F7: U8, Ro, Live, Span(0, 30), default 0, None, "not-moving code";
    /// Fault detection mask (our object; seed 003's 0x201B): a detection whose bit is clear
    /// latches nothing. Bit 0 the over-current by the measured currents (0x2133; the trip in
    /// hardware turns the bridges off and latches it whatever this says), 1 the over-voltage,
    /// 2 the parameter store's failure (alarm 32: 0x2120 found corrupt at power-up or a save
    /// that failed; the manual's EEPROM), 3 the overspeed (0x21F6, alarm 31), 6 the
    /// under-voltage, 7 the phase loss, 11 the current sensing's check at power-up (alarm 33;
    /// the manual's op-amp fault). The other bits have no detection behind them: a write that
    /// sets one is refused. The over-temperature, the overload and the encoder lost have no bit
    /// (they protect the drive and the motor).
    FaultMask @ 0x21F8: U16, Rw, Rom, Bits(0x08CF), default 0x08CB, None, "fault detection mask";
    /// IN1 filter time (our object; seed 003's 0x2023.1; IN2-IN7 are 0x21FA-0x21FF), µs: a
    /// change of the input's level counts once it has held this long, counting the tick it came
    /// at (its bounces meanwhile ignored), for its function, its state in 0x21D3 and a touch
    /// probe's capture (the position where the change began); the external stops' delay 0x6042
    /// is the same debouncer's. 50, one control tick, takes every change at once.
    InputFilter1 @ 0x21F9: U16, Rw, Rom, Span(50, 60_000), default 50, Micros, "IN1 filter time";
    /// IN2 filter time (our object; seed 003's 0x2023.2): as 0x21F9.
    InputFilter2 @ 0x21FA: U16, Rw, Rom, Span(50, 60_000), default 50, Micros, "IN2 filter time";
    /// IN3 filter time (our object; seed 003's 0x2023.3): as 0x21F9.
    InputFilter3 @ 0x21FB: U16, Rw, Rom, Span(50, 60_000), default 50, Micros, "IN3 filter time";
    /// IN4 filter time (our object; seed 003's 0x2023.4): as 0x21F9.
    InputFilter4 @ 0x21FC: U16, Rw, Rom, Span(50, 60_000), default 50, Micros, "IN4 filter time";
    /// IN5 filter time (our object; seed 003's 0x2023.5): as 0x21F9.
    InputFilter5 @ 0x21FD: U16, Rw, Rom, Span(50, 60_000), default 50, Micros, "IN5 filter time";
    /// IN6 filter time (our object): as 0x21F9.
    InputFilter6 @ 0x21FE: U16, Rw, Rom, Span(50, 60_000), default 50, Micros, "IN6 filter time";
    /// IN7 filter time (our object): as 0x21F9.
    InputFilter7 @ 0x21FF: U16, Rw, Rom, Span(50, 60_000), default 50, Micros, "IN7 filter time";
    /// Command filter (our object; seed 003's 0x2015): 1 smooths the position command by a
    /// moving average over 0x2211 before the motor follows it (`motion::shaping`): a master's
    /// position steps become motion at a bounded acceleration, delayed by half the time, and a
    /// move still ends exactly on its target; 0 off. Every command passes through it (moves,
    /// PVT, pulse following, homing); 0x600E reads the command, and the busy bit (0x6001 bit 3)
    /// stays set until the motor stands on it. A change takes effect once the filter's output
    /// stands on its input.
    CommandFilter @ 0x2210: U8, Rw, Rom, Span(0, 1), default 0, None, "command filter";
    /// Command filter time (our object; seed 003's 0x2016), µs: the moving average's length, to
    /// the nearest control tick (50 µs; 25.6 ms at most, 512 ticks).
    CommandFilterTime @ 0x2211: U16, Rw, Rom, Span(50, 25_600), default 1000, Micros, "command filter time";
    /// Scope signal 1 (our object): the code of the 1st signal of a row (`scope::Signal`, listed
    /// with their units and words under "The scope" below); 0 none. Takes effect at the next arm.
    ScopeSignal1 @ 0x2220: U8, Rw, Ram, Span(0, 15), default 1, None, "scope signal 1";
    /// Scope signal 2 (our object): the code of the 2nd signal of a row (`scope::Signal`, listed
    /// with their units and words under "The scope" below); 0 none. Takes effect at the next arm.
    ScopeSignal2 @ 0x2221: U8, Rw, Ram, Span(0, 15), default 2, None, "scope signal 2";
    /// Scope signal 3 (our object): the code of the 3rd signal of a row (`scope::Signal`, listed
    /// with their units and words under "The scope" below); 0 none. Takes effect at the next arm.
    ScopeSignal3 @ 0x2222: U8, Rw, Ram, Span(0, 15), default 3, None, "scope signal 3";
    /// Scope signal 4 (our object): the code of the 4th signal of a row (`scope::Signal`, listed
    /// with their units and words under "The scope" below); 0 none. Takes effect at the next arm.
    ScopeSignal4 @ 0x2223: U8, Rw, Ram, Span(0, 15), default 4, None, "scope signal 4";
    /// Scope signal 5 (our object): the code of the 5th signal of a row (`scope::Signal`, listed
    /// with their units and words under "The scope" below); 0 none. Takes effect at the next arm.
    ScopeSignal5 @ 0x2224: U8, Rw, Ram, Span(0, 15), default 0, None, "scope signal 5";
    /// Scope signal 6 (our object): the code of the 6th signal of a row (`scope::Signal`, listed
    /// with their units and words under "The scope" below); 0 none. Takes effect at the next arm.
    ScopeSignal6 @ 0x2225: U8, Rw, Ram, Span(0, 15), default 0, None, "scope signal 6";
    /// Scope signal 7 (our object): the code of the 7th signal of a row (`scope::Signal`, listed
    /// with their units and words under "The scope" below); 0 none. Takes effect at the next arm.
    ScopeSignal7 @ 0x2226: U8, Rw, Ram, Span(0, 15), default 0, None, "scope signal 7";
    /// Scope signal 8 (our object): the code of the 8th signal of a row (`scope::Signal`, listed
    /// with their units and words under "The scope" below); 0 none. Takes effect at the next arm.
    ScopeSignal8 @ 0x2227: U8, Rw, Ram, Span(0, 15), default 0, None, "scope signal 8";
    /// Scope divider (our object): a row every this many control ticks (50 µs each; every second
    /// tick at the most, 10 kHz: a row costs the tick about 400 instructions, which at every
    /// tick would take the servo loop's tick over its 30 % of the period).
    ScopeDivider @ 0x2228: U16, Rw, Ram, Span(2, 10_000), default 2, None, "scope divider";
    /// Scope trigger (our object): 0 at once, 1 a motion starts (the busy bit rises), 2 the
    /// trigger signal 0x222A rises to the level 0x222B or above, 3 falls to it or below, 4
    /// crosses it either way, 5 a bit of the mask 0x222B turns on in it, 6 turns off, 7 an alarm
    /// is recorded. Watched at each row.
    ScopeTrigger @ 0x2229: U8, Rw, Ram, Span(0, 7), default 0, None, "scope trigger";
    /// Scope trigger signal (our object): the signal 0x2229's level and bit triggers watch.
    ScopeTriggerSignal @ 0x222A: U8, Rw, Ram, Span(0, 15), default 0, None, "scope trigger signal";
    /// Scope trigger level (our object): in the trigger signal's unit; the bits' mask for
    /// triggers 5 and 6.
    ScopeTriggerLevel @ 0x222B: S32, Rw, Ram, S32_ANY, default 0, None, "scope trigger level";
    /// Scope pre-trigger (our object): the share of the capture before the trigger.
    ScopePreTrigger @ 0x222D: U8, Rw, Ram, Span(0, 100), default 10, Percent, "scope pre-trigger";
    /// Scope mode (our object): 0 one shot; 1 repeated (armed again when a capture is read,
    /// 0x2232).
    ScopeMode @ 0x222E: U8, Rw, Ram, Span(0, 1), default 0, None, "scope mode";
    /// Scope control (our object): 1 arms the scope with 0x2220-0x222E (refused, 04, without a
    /// signal or with a trigger that watches none); 0 stops it and drops its capture. While it
    /// records, the black box pauses.
    ScopeControl @ 0x222F: U8, Cmd, Ram, Span(0, 1), default 0, None, "scope control";
    /// Scope state (our object): 0 idle, 1 armed, 2 triggered, 3 a capture held (rows at
    /// 0x4000-0x5FFF).
    ScopeState @ 0x2230: U8, Ro, Live, Span(0, 3), default 0, None, "scope state";
    /// Scope sequence (our object): captures finished since power-up, wrapping; the number of
    /// the capture held. Read with 0x2230 before and after the rows: the same number, 3 both
    /// times, is a whole capture.
    ScopeSequence @ 0x2231: U16, Ro, Live, Any, default 0, None, "scope sequence";
    /// Scope read (our object): write the number of the capture read; a repeated scope arms
    /// again, a one-shot one goes idle. Another number is ignored.
    ScopeRead @ 0x2232: U16, Cmd, Ram, Any, default 0, None, "scope read";
    /// Scope rows (our object): the rows of the capture held (0 while none is).
    ScopeRows @ 0x2233: U16, Ro, Live, Any, default 0, None, "scope rows";
    /// Scope row words (our object): the registers a row takes at 0x4000 (a signal's one or
    /// two, in the order of 0x2220-0x2227).
    ScopeRowWords @ 0x2234: U8, Ro, Live, Any, default 0, None, "scope row words";
    /// Scope trigger row (our object): the row of the capture where it triggered.
    ScopeTriggerRow @ 0x2235: U16, Ro, Live, Any, default 0, None, "scope trigger row";
    /// Scope row period (our object), µs: the mean time between the capture's rows after its
    /// trigger, as the drive's clock measured it (0x2228 ticks of 50 µs on the board); 0 while
    /// none is held.
    ScopeRowPeriod @ 0x2236: U32, Ro, Live, Any, default 0, Micros, "scope row period";
    /// Black box state (our object): 1 recording (paused while the scope records), 3 a capture
    /// held (rows at 0xA000-0xBFFF) since an alarm: the second before it and a quarter after.
    BlackBoxState @ 0x2238: U8, Ro, Live, Span(0, 3), default 1, None, "black box state";
    /// Black box sequence (our object): as 0x2231, for the black box.
    BlackBoxSequence @ 0x2239: U16, Ro, Live, Any, default 0, None, "black box sequence";
    /// Black box read (our object): write the number of the capture read; the black box
    /// records again.
    BlackBoxRead @ 0x223A: U16, Cmd, Ram, Any, default 0, None, "black box read";
    /// Black box rows (our object): the rows of the capture held (8 registers each).
    BlackBoxRows @ 0x223B: U16, Ro, Live, Any, default 0, None, "black box rows";
    /// Black box trigger row (our object): the row of the alarm.
    BlackBoxTriggerRow @ 0x223C: U16, Ro, Live, Any, default 0, None, "black box trigger row";
    /// Black box fault (our object): the fault history entry (as 0x213C-0x214F hold it: code and
    /// time) of the alarm the capture holds; 0 while none is held.
    BlackBoxFault @ 0x223D: U32, Ro, Live, Any, default 0, None, "black box fault";
    /// Black box row period (our object), µs: as 0x2236, for the black box.
    BlackBoxRowPeriod @ 0x223F: U32, Ro, Live, Any, default 0, Micros, "black box row period";
    /// Update state (our object): where the image transfer (function 0x15, `updates.md`) stands:
    /// 0 idle, 1 receiving, 2 verifying (the image whole, its signature good, its trailer being
    /// written), 3 ready to install, 4 failed (0x2251 says why; the running image stays), 5
    /// installing.
    UpdateState @ 0x2250: U8, Ro, Live, Span(0, 5), default 0, None, "update state";
    /// Update failure (our object): why 0x2250 reads 4: 1 not an image, 2 for another board, 3
    /// installed with fewer bytes than its header says, 4 its signature (unsigned, another key,
    /// changed since signed), 5 it needs a newer parameter store, 6 longer than a slot takes,
    /// 7 the flash did not take it or hold it. 0 otherwise.
    UpdateReason @ 0x2251: U8, Ro, Live, Span(0, 7), default 0, None, "update failure";
    /// Update received (our object): the image's bytes taken, in order from its first.
    UpdateReceived @ 0x2252: U32, Ro, Live, Any, default 0, Bytes, "update received";
    /// Update length (our object): the image's whole length (header, program, signature) once its
    /// header has come; 0 before.
    UpdateLength @ 0x2254: U32, Ro, Live, Any, default 0, Bytes, "update length";
    /// Update control (our object): 1 abandons the transfer; 2 installs the image ready (0x2250
    /// = 3): checked once more as the slot holds it, marked for the boot loader, and the drive
    /// restarts into it once the reply has gone. 2 is refused (04) while the axis moves or a save
    /// is under way, or with no image ready; an image that stopped short fails for 3.
    UpdateControl @ 0x2256: U8, Cmd, Ram, Span(0, 2), default 0, None, "update control";
    /// Update version (our object): the received image's version, as its header says:
    /// major << 16 | minor << 8 | patch; 0 until its header has come.
    UpdateVersion @ 0x2257: U32, Ro, Live, Any, default 0, None, "update version";
    /// Firmware version (our object): the running image's, major << 16 | minor << 8 | patch.
    FirmwareVersion @ 0x2259: U32, Ro, Live, Any, default 0, None, "firmware version";
    /// Firmware key (our object): 0 the drive takes images signed with its maker's key; 1 with
    /// the repository's test key, which anyone can sign with (not for a machine in service);
    /// 2 it takes no images (a platform without the slots).
    FirmwareKey @ 0x225B: U8, Ro, Live, Span(0, 2), default 2, None, "firmware key";
    /// Write lock (our object): 0 no password is set; 1 locked: every write and update but
    /// 0x225F is refused with exception 01 (FSET still restores the factory settings, which have
    /// no password); 2 unlocked by 0x225F until the next power-up.
    WriteLock @ 0x225C: U8, Ro, Live, Span(0, 2), default 0, None, "write lock";
    /// Password (our object): a number other than 0 locks the drive's writes at every power-up
    /// (0x225C) once saved (0x200F = 2); 0 no lock. Setting it leaves the drive unlocked until
    /// the next power-up. Reads 0: the password is not told.
    Password @ 0x225D: U32, Rw, Rom, Any, default 0, None, "password";
    /// Unlock (our object): the password unlocks the drive's writes until the next power-up; 0
    /// locks them again. Any other number is refused (03) and changes nothing.
    Unlock @ 0x225F: U32, Cmd, Ram, Any, default 0, None, "unlock";
    /// Firmware state (our object): what the boot loader's state says of the running image: 0
    /// confirmed (or never updated); 1 on trial, swapped in at the last reset: it confirms itself
    /// once it has answered a request, else the next reset swaps the image before back; 2 rolled
    /// back: the last update did not confirm itself and was swapped back out; 3 an update is
    /// marked for the next reset (on a board without a boot loader, QEMU's, it stays marked).
    FirmwareState @ 0x2261: U8, Ro, Live, Span(0, 3), default 0, None, "firmware state";
    /// Error status, write 1 to clear: bit 0 over-temperature (0x2132), 1 coil A open, 2 coil B
    /// open (the power stage's open-load flags), 3 A over-current, 4 B over-current (0x2133),
    /// 5 under-voltage (0x2130). A set bit latches the safe state: power stage off, brake
    /// applied, axis stopped, moves refused (04). A condition still present sets it again.
    ErrorStatus @ 0x6000: U8, W1c, Live, Bits(0x3F), default 0, None, "error status";
    /// Controller status, write 1 to clear (bit 3 excepted): bit 0 external stop 1, 1 external
    /// stop 2, 2 stall, 3 busy (moving), 4 external stop 3, 5 PVT FIFO empty, 6 FIFO below the low
    /// mark, 7 FIFO above the high mark.
    ControllerStatus @ 0x6001: U8, W1c, Live, Bits(0xFF), default 0, None, "controller status";
    /// Direction of relative moves: 0 forward, 1 reverse.
    Direction @ 0x6002: U8, Rw, Ram, Span(0, 1), default 0, None, "direction";
    /// Maximum (run) speed. In velocity mode its sign is the direction.
    MaxSpeed @ 0x6003: S32, Rw, Ram, Span(-200_000, 200_000), default 0, Pps, "maximum speed";
    /// Relative move: completing the value (low word) starts a move of that many steps in the
    /// direction of 0x6002; a negative count moves the opposite way. Signed as appendix 1 types
    /// it (INT32; chapter 5 prints U32): a master that writes -3200 means 3200 steps back.
    RelativeMove @ 0x6005: S32, Cmd, Ram, S32_ANY, default 0, Steps, "relative move";
    /// Work mode: 0 position, 1 velocity, 2 PVT, 4 profile position (PP), 5 profile velocity (PV),
    /// 6 homing (ours: the device controlword 0x2180 starts the homing of 0x2160), 3 pulse
    /// following (the manual's encoder follower): the setpoint follows the pulse input in the
    /// format of 0x21B7, one microstep a pulse, while the power stage is on and no stop is
    /// latched; motion writes are refused (04) meanwhile. Entered standing (else 04).
    Mode @ 0x6007: U8, Rw, Ram, Set(MODES), default 0, None, "work mode";
    /// Start speed of the S-curve (chapter 5 prints 0x6006, which collides with 0x6005..6).
    StartSpeed @ 0x6008: U16, Rw, Rom, Any, default 600, Pps, "start speed";
    /// Stop speed of the S-curve.
    StopSpeed @ 0x6009: U16, Rw, Rom, Any, default 600, Pps, "stop speed";
    /// Acceleration level: 1..8 = 77440, 48410, 27170, 21510, 14080, 10460, 6915, 5210 pps²;
    /// 0 disables the ramp.
    AccelLevel @ 0x600A: U8, Rw, Rom, Span(0, 8), default 8, None, "acceleration level";
    /// Deceleration level, as 0x600A.
    DecelLevel @ 0x600B: U8, Rw, Rom, Span(0, 8), default 8, None, "deceleration level";
    /// Microstep resolution: microsteps per full step; 0 is full stepping, like 1. The manual
    /// lists 0, 2, 4, ..., 256; the drive runs any whole count up to 256 (seed 003's pulses a
    /// revolution, any multiple of 200, needs them: 10 000 is 50).
    Microsteps @ 0x600C: U16, Rw, Rom, Span(0, 256), default 0, None, "microstep resolution";
    /// Phase current (peak of a phase).
    PhaseCurrent @ 0x600D: U16, Rw, Rom, Span(0, 6000), default 658, MilliAmps, "phase current";
    /// Motor position. Writing it sets the current position without moving.
    Position @ 0x600E: S32, Rw, Live, S32_ANY, default 0, Steps, "motor position";
    /// Current decay: the share of fast decay in the chopper's off-time, 0 0 % (slow decay only),
    /// 1 50 %, 2 75 %, 3 87.5 %. More fast decay lets the current fall faster at speed, at the
    /// cost of ripple. The drive's own bridges have no chopper: there it sets how fast the current
    /// loop follows, 0 slowest and quietest to 3 fastest (`windings::DECAY_GAINS`: the gains of
    /// 0x210C and 0x210D, which are the factory decay's, times 0.625, 0.8125, 1 and 1.125). (The
    /// standstill current reduction is 0x2102/0x2103.)
    CurrentDecay @ 0x6010: U8, Rw, Rom, Span(0, 3), default 2, None, "current decay";
    /// Motor enable: 0 frees the motor (current off) and ignores moves until 1.
    Enable @ 0x6011: U8, Rw, Ram, Span(0, 1), default 1, None, "motor enable";
    /// External stop enable (§5.6): bit 0 EXT1, bit 1 EXT2, bit 4 EXT3. An enabled input's
    /// edge (0x6014), confirmed after 0x6042, stops the motor in that control tick with the
    /// moves' deceleration (0x600B's level; 0x6069 in PP/PV), sets its bit of 0x6001 (0, 1, 4),
    /// and moves are refused (04) until the master clears it.
    ExtStopEnable @ 0x6013: U8, Rw, Rom, Bits(0x13), default 0, None, "external stop enable";
    /// External stop trigger edge, per bit as 0x6013: 0 falling, 1 rising.
    ExtStopTrigger @ 0x6014: U8, Rw, Rom, Bits(0x13), default 0, None, "external stop trigger";
    /// Sensor type, as §5.6.3 has it: 0 pulls an enabled EXT input against its edge (falling:
    /// up, rising: down), so that the sensor's actuation drives the pin against the pull: an NPN
    /// output or a contact to ground on the falling edge, a PNP output on the rising edge. 1 pulls
    /// with the edge (rising: up, falling: down): the edge is then a sensor letting go. It sets
    /// the pulls of enabled EXT inputs in place of their 0x602F fields.
    SensorType @ 0x6015: U8, Rw, Rom, Span(0, 1), default 0, None, "sensor type";
    /// PVT operation (chapter 5 prints 0x6016): 0 stop (decelerate to rest), 1 start (at the
    /// control tick a board's planning margin after the frame), 2 push the point 0x6027..2C into the queue (refused, 04, when full or when
    /// its segment from the previous point would exceed 200 kpps or jump), 3 clear the queue
    /// (refused while running). See `drive-core/src/state/pvt.rs` for runs and their checks.
    PvtControl @ 0x6017: U8, Cmd, Ram, Span(0, 3), default 0, None, "PVT operation";
    /// PVT mode: 0 mode 1 (single run), 1 mode 2 (loop), 2 mode 3 (FIFO). Changing it clears
    /// the points; refused while a run is active.
    PvtMode @ 0x6018: U8, Rw, Ram, Span(0, 2), default 0, None, "PVT mode";
    /// Maximum number of PVT points in modes 1 and 2 (0: the whole table, 1000).
    PvtMaxPoints @ 0x6019: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT maximum points";
    /// Current PVT point index: the table (or ring) index of the point the running segment
    /// heads to.
    PvtPointer @ 0x601A: U16, Ro, Live, PVT_INDEX, default 0, None, "PVT pointer";
    /// PVT mode 1: first point.
    PvtM1Start @ 0x601B: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT mode 1 start index";
    /// PVT mode 1: last point.
    PvtM1End @ 0x601C: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT mode 1 end index";
    /// PVT mode 2: first point of the acceleration phase.
    PvtM2AccStart @ 0x601D: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT mode 2 acceleration start";
    /// PVT mode 2: last point of the acceleration phase.
    PvtM2AccEnd @ 0x601E: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT mode 2 acceleration end";
    /// PVT mode 2: first point of the loop phase.
    PvtM2LoopStart @ 0x601F: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT mode 2 loop start";
    /// PVT mode 2: last point of the loop phase.
    PvtM2LoopEnd @ 0x6020: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT mode 2 loop end";
    /// PVT mode 2: how many times the loop phase runs (0: skipped).
    PvtM2Loops @ 0x6021: U16, Rw, Ram, Any, default 0, None, "PVT mode 2 loop count";
    /// PVT mode 2: first point of the deceleration phase.
    PvtM2DecStart @ 0x6022: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT mode 2 deceleration start";
    /// PVT mode 2: last point of the deceleration phase.
    PvtM2DecEnd @ 0x6023: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT mode 2 deceleration end";
    /// PVT mode 3: FIFO depth, the most points queued (0: 1000).
    PvtFifoDepth @ 0x6024: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT FIFO depth";
    /// PVT mode 3: below this many points the low-mark status bit is set.
    PvtFifoLow @ 0x6025: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT FIFO low mark";
    /// PVT mode 3: above this many points the high-mark status bit is set.
    PvtFifoHigh @ 0x6026: U16, Rw, Ram, PVT_INDEX, default 0, None, "PVT FIFO high mark";
    /// PVT point: absolute position.
    PvtPosition @ 0x6027: S32, Rw, Ram, S32_ANY, default 0, Steps, "PVT position";
    /// PVT point: velocity.
    PvtVelocity @ 0x6029: S32, Rw, Ram, S32_ANY, default 0, Pps, "PVT velocity";
    /// PVT point: time since the previous point. The table keeps 16 bits: at most 65.535 s.
    PvtTime @ 0x602B: S32, Rw, Ram, Span(0, 65_535), default 0, Millis, "PVT time";
    /// GPIO direction, 1 output: bits 0-6 GPIO1-7, 11 GPIO8. Bits 7-10 (EXT1-3, ENC2) are
    /// inputs and cannot be set.
    GpioDirection @ 0x602E: U16, Rw, Rom, Bits(0x087F), default 0, None, "GPIO direction";
    /// GPIO configuration, 2 bits a pin (GPIO1 in bits 1-0 .. GPIO8 in 23-22): inputs 0 floating,
    /// 1 pull-up, 2 pull-down, 3 analog; outputs 0 open drain, 1 push-pull. The manual's range
    /// 0-0x3FFFF stops short of its own GPIO8 field; we accept all 24 bits.
    GpioConfig @ 0x602F: U32, Rw, Rom, Bits(0x00FF_FFFF), default 0, None, "GPIO configuration";
    /// GPIO levels, inverted as the manual says (0 high, 1 low); writes affect outputs only.
    GpioValue @ 0x6031: U16, Rw, Live, Bits(0x0FFF), default 0, None, "GPIO value";
    /// Coil output PWM duty (Coil+/Coil-, at the supply voltage, up to 800 mA): a brake's release
    /// duty or a general output's, as 0x2151 chooses; a duty under 100 keeps a held coil cooler.
    /// 0: off.
    Brake @ 0x6038: U8, Rw, Ram, Span(0, 100), default 0, Percent, "brake control";
    /// Open-loop stall detection: bits 0-6 the threshold, signed (typically -10..10): the load
    /// angle limit is 110° − 4° × threshold, so a larger threshold detects sooner (see
    /// `drive_core::servo`); bits 7-15 reserved. Detection itself is switched by 0x2107.
    StallParams @ 0x6039: U16, Rw, Rom, Bits(0x7F), default 0, None, "stall parameters";
    /// EXT1/2/3 stabilisation delay: an edge counts only if the input still has the edge's
    /// level this long after it (bounces in between are ignored); 0 acts on the edge. The
    /// external stops' debouncer, the one IN1-IN7's filter times set (0x21F9-0x21FF).
    ExtDebounce @ 0x6042: U16, Rw, Rom, Span(0, 200), default 100, Millis, "EXT debounce";
    /// Stop on stall (open loop): 1 stops the motor when a stall is detected.
    StallStop @ 0x6043: U8, Rw, Rom, Span(0, 1), default 0, None, "stop on stall";
    /// Absolute move: completing the value starts a move to this position.
    AbsoluteMove @ 0x6044: S32, Cmd, Ram, S32_ANY, default 0, Steps, "absolute move";
    /// Synchronous positioning: speed.
    SyncSpeed @ 0x6047: S32, Rw, Ram, S32_ANY, default 0, Pps, "sync speed";
    /// Synchronous positioning: target position (printed 0x6049..5a).
    SyncPosition @ 0x6049: S32, Rw, Ram, S32_ANY, default 0, Steps, "sync position";
    /// Stop: writing 0 stops the motor at once, in any mode.
    Stop @ 0x6053: U8, Cmd, Ram, Span(0, 0), default 0, None, "stop";
    /// Encoder resolution: lines per revolution (counted ×4), or 12 for the 12-bit absolute
    /// encoder. Takes effect after a restart.
    EncoderCpr @ 0x6054: U16, Rw, Rom, Set(ENCODER_CPR), default 1000, None, "encoder resolution";
    /// Position saved at the last power loss (see 0x605E): its own small record in flash, loaded
    /// at power-up; a save (0x200F = 2) neither writes nor clears it.
    SavedPosition @ 0x6055: S32, Ro, Rom, S32_ANY, default 0, Steps, "power-down position";
    /// Closed loop: proportional gain; servo loop: KP/16 of the full current per full step of error.
    Kp @ 0x6057: U8, Rw, Rom, Span(1, 255), default 8, None, "KP";
    /// Closed loop: integral gain; servo loop: 5·KI of the full current per full step·second.
    Ki @ 0x6058: U8, Rw, Rom, Span(1, 255), default 4, None, "KI";
    /// Closed loop: derivative gain; servo loop: KD/4 of the full current per full step per ms.
    Kd @ 0x6059: U8, Rw, Rom, Span(1, 255), default 8, None, "KD";
    /// Closed loop: prefilter: the servo loop low-passes the error's rate over this many control
    /// ticks (the manual: larger at high speed, no larger than the microstep resolution).
    PreFilter @ 0x605A: U8, Rw, Rom, Span(1, 128), default 32, None, "prefilter";
    /// Closed loop: postfilter. §5.8.6 reserves it ("暂时保留") and gives it no meaning: only its
    /// default 16 is accepted (a master that writes the manual's values goes through), any other
    /// value is refused (03) rather than stored to do nothing.
    PostFilter @ 0x605B: U16, Rw, Rom, Span(16, 16), default 16, None, "postfilter";
    /// Closed loop: following error, in microsteps of 0x600C, that counts as a stall and latches
    /// the position error (0x2135 bit 2, alarm 25) (chapter 5 prints 0x6028).
    StallLength @ 0x605C: U16, Rw, Rom, Span(1, 255), default 64, Steps, "stall length";
    /// Closed loop: 1 enables the torque (servo) loop with PID; 0 is the position loop.
    TorqueLoop @ 0x605D: U8, Rw, Rom, Span(0, 1), default 0, None, "torque loop enable";
    /// 1 saves the position (as 0x6055) when power loss is detected: one record of two flash
    /// writes, ~0.2 ms on the STM32G474 (~22 ms more if it falls at a page's end).
    AutoSave @ 0x605E: U8, Rw, Rom, Span(0, 1), default 0, None, "power-down save enable";
    /// Analog input, 12-bit ADC code. Read only here: the appendix's RW has no meaning for an input.
    AnalogIn @ 0x605F: U16, Ro, Live, Span(0, 4095), default 0, None, "analog input";
    /// Step notification status: bit 0 point 1 passed, bit 1 point 2 passed; write 1 to clear.
    NotifyStatus @ 0x6061: U8, W1c, Live, Bits(0x03), default 0, None, "step notify status";
    /// Step notification point 1, absolute.
    NotifyPos1 @ 0x6062: S32, Rw, Ram, Span(-i32::MAX, i32::MAX), default 0, Steps, "step notify position 1";
    /// Step notification point 2, absolute.
    NotifyPos2 @ 0x6064: S32, Rw, Ram, Span(-i32::MAX, i32::MAX), default 0, Steps, "step notify position 2";
    /// PP/PV acceleration.
    PpAccel @ 0x6067: U32, Rw, Rom, Span(151, i32::MAX), default 32000, Pps2, "PP acceleration";
    /// PP/PV deceleration.
    PpDecel @ 0x6069: U32, Rw, Rom, Span(151, i32::MAX), default 32000, Pps2, "PP deceleration";
    /// PP/PV start speed.
    PpStartSpeed @ 0x606B: U32, Rw, Rom, Span(151, 300_000), default 600, Pps, "PP start speed";
    /// PP/PV stop speed.
    PpStopSpeed @ 0x606D: U32, Rw, Rom, Span(151, 300_000), default 600, Pps, "PP stop speed";
    /// PP/PV controlword: bit 4 new set-point (rising edge), 5 change immediately, 6 relative,
    /// 8 halt, 9 change on set-point without stopping.
    ControlWord @ 0x6070: U16, Rw, Ram, Any, default 0, None, "controlword";
    /// PP/PV statusword: bit 10 target reached, 12 set-point acknowledge.
    StatusWord @ 0x6071: U16, Ro, Live, Any, default 0, None, "statusword";
    /// PP/PV run speed; its sign is the direction.
    PpRunSpeed @ 0x6072: S32, Rw, Ram, Magnitude(150, 300_000), default 32000, Pps, "PP run speed";
    /// PP target position.
    PpTarget @ 0x6074: S32, Rw, Ram, S32_ANY, default 0, Steps, "PP target position";
    /// Analog positioning (§5.13): 1 makes the analog input set the target position in the PP
    /// mode (0x6007 = 4, the mode the manual names for it), with the PP mode's speed and ramps:
    /// readings averaged over 0x6079, a move planned when the position differs from the target
    /// in force by more than 0x607A (see `drive_core::state::analog`).
    AnalogPosEnable @ 0x6077: U8, Rw, Rom, Span(0, 1), default 0, None, "analog positioning enable";
    /// Analog positioning: ADC code of the minimum position.
    AnalogStartCode @ 0x6078: U16, Rw, Rom, Span(0, 4096), default 0, None, "analog start code";
    /// Analog positioning: adjustment interval (at least 10 ms): the readings of each interval
    /// are averaged.
    AnalogInterval @ 0x6079: U16, Rw, Rom, Any, default 100, Millis, "analog interval";
    /// Analog positioning: the dead band: a move is planned when the input's position differs
    /// from the target in force by more than this.
    AnalogTrigger @ 0x607A: U16, Rw, Rom, Any, default 30, Steps, "analog trigger";
    /// Analog positioning: position at the start code.
    AnalogMinPos @ 0x607B: S32, Rw, Rom, S32_ANY, default 0, Steps, "analog minimum position";
    /// Analog positioning: position at code 4095.
    AnalogMaxPos @ 0x607D: S32, Rw, Rom, S32_ANY, default 64000, Steps, "analog maximum position";
    /// Real-time speed: closed loop the encoder's, low-passed over ~13 ms (counts a second); open
    /// loop the commanded speed. Read only.
    RealSpeed @ 0x607F: S32, Ro, Live, Span(-300_000, 300_000), default 0, Pps, "real-time speed";
    /// Power-loss behaviour: bit 0 free the motor (power stage off, axis stopped, moves refused)
    /// below 0x6083, bit 1 apply the brake below 0x6084, while the supply stays below. Not
    /// latched. Falling below the highest of the enabled levels and 0x2130 requests the
    /// power-down position save (0x605E) once.
    PowerLossControl @ 0x6082: U16, Rw, Rom, Bits(0x03), default 0, None, "power-loss control";
    /// Power loss: supply voltage below which the motor is freed.
    PowerLossFreeVoltage @ 0x6083: U16, Rw, Rom, Any, default 0, MilliVolts, "power-loss free voltage";
    /// Power loss: supply voltage below which the brake is applied.
    PowerLossBrakeVoltage @ 0x6084: U16, Rw, Rom, Any, default 0, MilliVolts, "power-loss brake voltage";
    /// Zero offset, closed loop: motor position = encoder position + zero offset. Writing the
    /// position 0x600E sets it; written itself (only while standing, else 04) it moves the
    /// position with it.
    ZeroOffset @ 0x6087: S32, Rw, Ram, S32_ANY, default 0, Counts, "zero calibration";
    /// Encoder position. Read only: it is a measurement.
    EncoderPosition @ 0x6089: S32, Ro, Live, S32_ANY, default 0, Counts, "encoder position";
}
