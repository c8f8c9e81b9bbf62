//! The DS-CLS9-FRS4 map (seed 002): decimal register numbers (§九), speeds in 0.01 rev/s and
//! accelerations in rev/s², the resolution in pulses a revolution, 32-bit values high word first
//! and written whole, and the control command 0323 as the drive's motion command 0x21A0.
//!
//! ```
//! use drive_core::maps::Maps;
//! use drive_core::od::Obj;
//! use drive_core::{Drive, DriveConfig, Instant};
//! let mut drive = Drive::with_map(DriveConfig::default(), Maps::cls9());
//! // 0306 (fixed-length speed) = 500, 5 rev/s: 1 000 full steps a second.
//! drive.on_rx(Instant::from_micros(0), &[0x01, 0x06, 0x01, 0x32, 0x01, 0xF4, 0x29, 0xEE]);
//! drive.on_timer(Instant::from_micros(4_011));
//! assert!(drive.take_reply().is_some());
//! assert_eq!(drive.state().read(Obj::CommandSpeed), 1_000);
//! ```

use super::compiled::Compiled;
use super::layout::{Choice, Entry, Exceptions, Layout, ProgramWindow, Scale, SpoiltCodes, Walk, WordOrder, ZERO_ONE};
use crate::od::Obj;

/// 0.01 rev/s in the drive's microsteps a second.
const CENTI_REV: Scale = Scale::PerRev(1, 100);
/// rev/s² in the drive's microsteps a second squared.
const REV: Scale = Scale::PerRev(1, 1);

/// 0104 / 0242: pulses a revolution, the drive's microstep resolutions (1.8° motors).
static RESOLUTIONS: &[Choice] = &[
    Choice { lo: 200, hi: 200, drive: 0 },
    Choice { lo: 400, hi: 400, drive: 2 },
    Choice { lo: 800, hi: 800, drive: 4 },
    Choice { lo: 1600, hi: 1600, drive: 8 },
    Choice { lo: 3200, hi: 3200, drive: 16 },
    Choice { lo: 6400, hi: 6400, drive: 32 },
    Choice { lo: 12_800, hi: 12_800, drive: 64 },
    Choice { lo: 25_600, hi: 25_600, drive: 128 },
    Choice { lo: 51_200, hi: 51_200, drive: 256 },
];

/// 0246: the encoder's counts a revolution (lines × 4), the drive's line counts.
static ENCODER: &[Choice] = &[
    Choice { lo: 800, hi: 800, drive: 200 },
    Choice { lo: 1600, hi: 1600, drive: 400 },
    Choice { lo: 2000, hi: 2000, drive: 500 },
    Choice { lo: 2400, hi: 2400, drive: 600 },
    Choice { lo: 3200, hi: 3200, drive: 800 },
    Choice { lo: 4000, hi: 4000, drive: 1000 },
    Choice { lo: 4800, hi: 4800, drive: 1200 },
    Choice { lo: 6400, hi: 6400, drive: 1600 },
];

/// 0206: 1 parameter reset (0x200F = 3), 2 alarm clear (0x200F = 4), 3 restart (0x200F = 1,
/// refused: the drive does not restart itself).
static USER_COMMAND: &[Choice] =
    &[Choice { lo: 1, hi: 1, drive: 3 }, Choice { lo: 2, hi: 2, drive: 4 }, Choice { lo: 3, hi: 3, drive: 1 }];

/// 0305: 0 clockwise (negative), 1 counter-clockwise (positive): the home switch searched that
/// way, reversing at that side's limit, then found again at the creep speed (0x2160 -9, -10).
static HOMING: &[Choice] = &[Choice { lo: 0, hi: 0, drive: 0xFFF7 }, Choice { lo: 1, hi: 1, drive: 0xFFF6 }];

/// 0106 / 0244: 1 pulse and direction, 2 double pulse (the drive's 0x21B7 also counts an
/// encoder's quadrature, 3, which this map does not offer).
static PULSE_FORMATS: &[Choice] = &[Choice { lo: 1, hi: 1, drive: 1 }, Choice { lo: 2, hi: 2, drive: 2 }];

/// 0296: 0 external pulses (the drive powers up following them, 0x21B9 = 1), 1 internal.
static PULSE_SOURCE: &[Choice] = &[Choice { lo: 0, hi: 0, drive: 1 }, Choice { lo: 1, hi: 1, drive: 0 }];

/// 0420-0423: 100 general, 101 alarm, 102 in position, 103 motor free (enable control), 104
/// ready; the drive's 0 (the pin a GPIO of the native map's) is not among them.
static OUTPUT_FUNCTIONS: &[Choice] = &[
    Choice { lo: 100, hi: 100, drive: 1 },
    Choice { lo: 101, hi: 101, drive: 2 },
    Choice { lo: 102, hi: 102, drive: 3 },
    Choice { lo: 103, hi: 103, drive: 4 },
    Choice { lo: 104, hi: 104, drive: 5 },
];

/// The registers, by address (decimal, as the manual's `adr` column), then ours at their
/// native addresses: the save (0x200F), the line's parity (0x2100), the homing's timeout and
/// switches (0x216B-0x216D) and the map selection (0x2190).
pub static ENTRIES: [Entry; 75] = [
    Entry::new(100, Obj::MotorCurrent, &Scale::Ratio(100, 1)),
    Entry::new(101, Obj::SupplyVoltage, &Scale::Ratio(1000, 1)),
    Entry::new(104, Obj::Microsteps, &Scale::Table(&RESOLUTIONS)).wide().read_only(),
    Entry::new(106, Obj::PulseFormat, &Scale::Table(&PULSE_FORMATS)).read_only(),
    Entry::new(108, Obj::AlarmCode, &Scale::One),
    Entry::new(109, Obj::RunState, &Scale::One),
    Entry::new(110, Obj::HardwareRevision, &Scale::One),
    Entry::new(111, Obj::SoftwareRevision, &Scale::One),
    Entry::new(117, Obj::TargetPosition, &Scale::One),
    Entry::new(119, Obj::RealSpeed, &CENTI_REV).narrow(),
    Entry::new(126, Obj::Position, &Scale::One).read_only(),
    Entry::new(174, Obj::ProgramInputSegment, &Scale::One),
    Entry::new(176, Obj::ProgramErrorSegment, &Scale::One),
    Entry::new(178, Obj::ProgramRunning, &Scale::One),
    Entry::new(201, Obj::MotorDirection, &Scale::One),
    Entry::new(206, Obj::SystemControl, &Scale::Table(&USER_COMMAND)),
    Entry::new(213, Obj::IdleCurrent, &Scale::One),
    Entry::new(217, Obj::Feedback, &Scale::Table(&ZERO_ONE)),
    Entry::new(234, Obj::PulseFilter, &Scale::One),
    Entry::new(241, Obj::PhaseCurrent, &Scale::One),
    Entry::new(242, Obj::Microsteps, &Scale::Table(&RESOLUTIONS)).wide(),
    Entry::new(244, Obj::PulseFormat, &Scale::Table(&PULSE_FORMATS)),
    Entry::new(245, Obj::IdleDelay, &Scale::One),
    Entry::new(246, Obj::EncoderCpr, &Scale::Table(&ENCODER)),
    Entry::new(247, Obj::InPositionWindow, &Scale::One).wide(),
    Entry::new(258, Obj::PositionErrorLimit, &Scale::One),
    Entry::new(296, Obj::PulseAtPowerUp, &Scale::Table(&PULSE_SOURCE)),
    Entry::new(298, Obj::NodeId, &Scale::One),
    Entry::new(299, Obj::BaudRate, &Scale::One),
    Entry::new(301, Obj::PpStartSpeed, &CENTI_REV).narrow(),
    Entry::new(302, Obj::PpStopSpeed, &CENTI_REV).narrow(),
    Entry::new(303, Obj::PpAccel, &REV).narrow(),
    Entry::new(304, Obj::PpDecel, &REV).narrow(),
    Entry::new(305, Obj::HomingMethod, &Scale::Table(&HOMING)),
    Entry::new(306, Obj::CommandSpeed, &CENTI_REV).narrow(),
    Entry::new(307, Obj::CommandVelocity, &CENTI_REV).narrow(),
    Entry::new(308, Obj::JogSpeed, &CENTI_REV).narrow(),
    Entry::new(309, Obj::HomingSearchSpeed, &CENTI_REV).narrow(),
    Entry::new(310, Obj::HomingCreepSpeed, &CENTI_REV).narrow(),
    Entry::new(311, Obj::HomingOffset, &Scale::One),
    Entry::new(313, Obj::CommandTarget, &Scale::One),
    Entry::new(317, Obj::SoftLimitPositive, &Scale::One),
    Entry::new(319, Obj::SoftLimitNegative, &Scale::One),
    Entry::new(321, Obj::PositionPreset, &Scale::One),
    Entry::new(323, Obj::MotionCommand, &Scale::One),
    Entry::new(324, Obj::SoftLimits, &Scale::One),
    Entry::new(327, Obj::ProgramSegments, &Scale::One),
    Entry::new(328, Obj::ProgramSelect, &Scale::One),
    Entry::new(400, Obj::InputFunction1, &Scale::One),
    Entry::new(401, Obj::InputFunction2, &Scale::One),
    Entry::new(402, Obj::InputFunction3, &Scale::One),
    Entry::new(403, Obj::InputFunction4, &Scale::One),
    Entry::new(404, Obj::InputFunction5, &Scale::One),
    Entry::new(405, Obj::InputFunction6, &Scale::One),
    Entry::new(406, Obj::InputFunction7, &Scale::One),
    Entry::new(410, Obj::PseudoInputs, &Scale::Field(0, 1)),
    Entry::new(411, Obj::PseudoInputs, &Scale::Field(1, 1)),
    Entry::new(412, Obj::PseudoInputs, &Scale::Field(2, 1)),
    Entry::new(413, Obj::PseudoInputs, &Scale::Field(3, 1)),
    Entry::new(414, Obj::PseudoInputs, &Scale::Field(4, 1)),
    Entry::new(415, Obj::PseudoInputs, &Scale::Field(5, 1)),
    Entry::new(416, Obj::PseudoInputs, &Scale::Field(6, 1)),
    Entry::new(420, Obj::OutputFunction1, &Scale::Table(&OUTPUT_FUNCTIONS)),
    Entry::new(421, Obj::OutputFunction2, &Scale::Table(&OUTPUT_FUNCTIONS)),
    Entry::new(422, Obj::OutputFunction3, &Scale::Table(&OUTPUT_FUNCTIONS)),
    Entry::new(423, Obj::OutputFunction4, &Scale::Table(&OUTPUT_FUNCTIONS)),
    Entry::new(428, Obj::GeneralOutputs, &Scale::One),
    Entry::new(429, Obj::InputLogic, &Scale::One),
    Entry::new(430, Obj::OutputLogic, &Scale::One),
    Entry::new(0x200F, Obj::SystemControl, &Scale::One),
    Entry::new(0x2100, Obj::Parity, &Scale::One),
    Entry::new(0x216B, Obj::HomingTimeout, &Scale::One),
    Entry::new(0x216C, Obj::HomingInputs, &Scale::One),
    Entry::new(0x216D, Obj::HomingPolarity, &Scale::One),
    Entry::new(0x2190, Obj::RegisterMap, &Scale::One),
];

/// The manual's codes (§十三): 02 no such register, 03 a value out of range, 04 any refusal of
/// the drive's (busy, disabled, faulted, not now); 0C and 0D for a frame's timing ([`SPOILT`]).
pub const EXCEPTIONS: Exceptions = Exceptions::MODBUS;

/// §十三's answers to a frame its timing spoilt: 0C for a silence over t1.5 inside it, 0D for a
/// frame that came before t3.5; a wrong CRC is dropped.
pub const SPOILT: SpoiltCodes = SpoiltCodes { gap: Some(0x0C), early: Some(0x0D), crc: None };

/// The multi-segment program's window: 1024-1536.
const PROGRAM: ProgramWindow = ProgramWindow {
    first: 1024,
    words: crate::state::memory::WORDS as u16,
    kind: crate::state::ProgramKind::Segments,
    check: None,
};

/// How a request walks [`ENTRIES`].
const WALK: Walk = Walk::Address;

/// The DS-CLS9 layout.
pub static LAYOUT: Layout = Layout {
    entries: &ENTRIES,
    order: WordOrder::HighFirst,
    exceptions: EXCEPTIONS,
    walk: WALK,
    halves: false,
    spoilt: SPOILT,
    defaults: &DEFAULTS,
    program: Some(PROGRAM),
    reserved: &[],
    sub_index: None,
    address: None,
    scope: true,
    index: Some(&INDEX),
};

/// The table's compiled lookup.
static INDEX: Compiled = compiled!(ENTRIES, WALK);

/// The manual's factory values (§九) where they differ from the drive's: start and stop
/// speeds 1 rev/s, ramps 100 rev/s², runs, jogs and homing at 10 rev/s, the homing clockwise,
/// OUT1 the alarm output and OUT2-OUT4 general outputs (0307's 10 rev/s is a speed, the drive's
/// run velocity as it stands).
static DEFAULTS: [(u16, i32); 14] = [
    (301, 100),
    (302, 100),
    (303, 100),
    (304, 100),
    (305, 0),
    (306, 1000),
    (307, 1000),
    (308, 1000),
    (309, 1000),
    (310, 1000),
    (420, 101),
    (421, 100),
    (422, 100),
    (423, 100),
];

/// What the reference says beside the table: the decisions where seed 002 is silent or
/// contradicts itself.
#[cfg(feature = "docs")]
pub static REFERENCE: super::doc::Reference = super::doc::Reference {
    title: "DS-CLS9-FRS4 map (seed 002)",
    notes: &[
        "Chosen with 0x2190 = 2, saved (0x200F = 2), from the next power-up; `hal-sim --map cls9` for one run. 0x2190 = 0 and a save switch back to the native map. Register numbers are decimal (0299 has two words and the next entry is 0301), and the drive's own registers keep their native (hexadecimal) numbers: 0x200F (8207) saves, 0x2100 (8448) the parity, 0x216B-0x216D (8555-8557) the homing's timeout and switches, 0x2190 (8592) the map.",
        "Parameters are kept by a save (0x200F = 2, as in the native map); the manual does not say when its drive stores them.",
        "Factory values: a drive with nothing saved in this map, and a parameter reset (0206 = 1), take the manual's where they differ from the drive's: 0301-0304 100, 0305 0, 0306-0310 1000, 0420 101, 0421-0423 100, in the resolution in force. The serial line stays at the drive's 9600 baud, 8N1, node 1 (0299's printed 19200 would make a fresh drive unreachable at the rate every other map starts at), 0217 at open loop (the manual's 1, closed loop, needs an encoder the drive may not have) and 0296 at internal pulses (see below). A drive switched from the native map keeps its saved values: the map changes the registers, not the settings.",
        "Functions 0x03, 0x06 and 0x10 (§十三), and the native map's 0x04, 0x08, 0x17 and 0x2B. A read takes up to 125 registers, a write up to 123. A request that covers a register number the table does not have (0102, 0105, ...) is refused with 02.",
        "32-bit values (two words) are high word first (§十二, big-endian) and written whole with 0x10: one half alone is refused with 02.",
        "Speeds are in 0.01 rev/s and accelerations in rev/s² of the resolution in force (0242: a revolution is 0242 pulses), converted exactly to the drive's microsteps (a revolution is 200 × the microsteps, so 0.01 rev/s is a whole number of microsteps a second); a drive value that is not a whole number of the map's units (one a native master wrote) reads rounded to the nearest. The drive runs 150 to 300 000 microsteps a second: a speed below that is refused (03). Start and stop speeds (0301, 0302) take 151 microsteps a second at least.",
        "0242 and 0104 (pulses a revolution) take the drive's resolutions 200, 400, 800, 1600, 3200, 6400, 12800, 25600 and 51200; others are refused (03). 0246 (encoder counts a revolution, lines × 4) takes 800, 1600, 2000, 2400, 3200, 4000, 4800 and 6400.",
        "0100 (motor current) reads in 0.1 A and 0101 (supply) in volts, as last measured; 0241 (current setting) in mA as the manual's range 100-4500 says.",
        "0108 is the drive's alarm code, which uses the manual's table 1-2: 10 over-current, 11 phase loss, 13 under-voltage, 14 over-voltage, 25 position error, 26 overload; 15 (over-temperature), 27 (encoder lost) and 30 (communication timeout, 0x2137) are the drive's own among \"other\". 0109 is table 1-1's run state: 1 enable off (or a fault), 2 standing, 3 running.",
        "0206 user command: 1 restores the factory parameters and saves them (0x200F = 3), 2 clears the alarms, 3 (restart) is refused (04): the drive does not restart itself; switch the power.",
        "0323 control command (the drive's 0x21A0): 1 absolute run to 0313 at 0306's speed, re-targeted when 0313 is written during the run; 2 relative run by 0313, refused (04) while moving (a write of 0313 during it changes nothing of the run); 3 run at 0307 (its sign the direction; a write of 0307 during it changes the speed); 4 and 5 jog at 0308 until 6 or 7; 6 stop at 0304; 7 stop at the quick-stop deceleration (0x2183, 320 000 microsteps/s² from the factory); 8 set the position to 0321, refused (04) while moving; 12 homing; 13 alarm clear; 14-18 the multi-segment program's check, save, start, pause and end (see below). Runs ramp at 0303/0304 from 0301 and down to 0302. A run is refused (04) with the power stage off or an alarm latched, and in the native map's PVT mode, where only 6 and 7 act (they end the PVT run). Reading 0323 gives the last command written.",
        "Soft limits 0317 / 0319 with 0324 bit 0 (positive) and bit 1 (negative): no motion command goes beyond an enabled limit; a target beyond it stops on it, a run or a jog towards it ends on it. Homing ignores them. 0324's other bits are refused (03).",
        "Homing (0323 = 12): 0305 0 searches the home switch clockwise (negative), 1 counter-clockwise, at 0309, reversing at the limit switch of that side, then finds the switch's edge again at the creep speed 0310; the home then reads as 0311. 0305 is 0 with the manual's factory values; on a drive switched from the native map it reads the drive's own method number until written (0x2160, the native factory 35: the home is where the axis stands). Which inputs are the home switch and the limit switches, and their levels, are the drive's 0x216C and 0x216D, and 0x216B is the timeout, in this map at their native addresses (8556-8557, 8555).",
        "Pulse input (the drive's work mode 3): with 0296 = 0, saved, the drive powers up following the step train on its pulse input (one pulse a microstep of 0242's resolution), in the format of 0244 (1 pulse and direction, DIR high counting down; 2 double pulse), through the input filter 0234 (1-15: a level must hold 2 to 256 clocks of 170 MHz, 12 ns to 1.5 µs). 0296 reads 1 (internal pulses) from the factory, not the manual's 0: the drive leaves the factory commanded over the bus, and a machine that steps it writes 0 and saves. While it follows, the control commands that move are refused (04) and 6 and 7 stop it where the pulses left it (it follows the next ones); 0109 reads 3 (running). 0244 and 0234 take effect at once, 0296 at the next power-up as the manual says.",
        "Inputs IN1-IN7 are the drive's EXT1-EXT3 and GPIO1-GPIO4 (on the G474 board EXT1-EXT3 only), outputs OUT1-OUT4 its GPIO5-GPIO8 (on the board GPIO8). 0400-0406 give each input a function, acted on when the input turns active (at 0429's level: bit k set, IN k+1 is active low) or when its pseudo-input 0410-0416 is written 1 (written 0 it is released): 1-8, 12, 13 the control command of that number (as a write of 0323, refused in the same cases, and then nothing moves); 9 and 10 the positive and negative limit switches (a motion heading into an active one stops at the drive's stop deceleration, and a command towards it is refused with 04; the homing reverses at them); 11 the home switch of the homing (over the drive's 0x216C); 20 enable (0x6011 takes the input's level whenever it changes, and at power-up). 14-18 the program commands of 0323; 25-29 bits 0-4 of the program segment a start runs (acted on by their level at the start, not by an edge). An input acts on its activation only, not while it stays active, and the levels at power-up are no activation. IN6 and IN7 stay inputs with external pulses: the drive's pulse input has lines of its own.",
        "0420-0423 give each output a function: 100 general (on while its bit of 0428 is set), 101 alarm (on while no alarm is latched), 102 in position (on while the axis stands on its target, within 0247 encoder counts in closed loop), 103 motor free (on while the power stage is off, the manual's 'enable control'), 104 ready (on while the power stage drives the motor; the manual lists 104 without saying what it is). 0430 bit k set makes OUT k+1 low when on. With the manual's factory values OUT1 is the alarm output (101) and OUT2-OUT4 general outputs (100); on a drive switched from the native map the outputs keep no function (0: the native map's GPIO) until 0420-0423 are written.",
        "Not in this map, answered 02: the angle filter 0224 and the loop gains 0251, 0252 and 0255. The drive's closed loop is one position loop (or its servo PID, 0x6057-0x605A in the native map) on the encoder, not the manual's speed loop inside a position loop, so the manual's gains and filter have no counterpart to act on. 0258 (position error threshold, encoder counts) is the drive's following-error limit: beyond it the closed loop latches alarm 25; 0 (the factory value; the manual gives none) leaves the drive's own limit, the native map's 0x605C (64 microsteps).",
        "Multi-segment programs (§7), registers 1024-1536: an instruction stream, each a code word and its parameter words (two-word values high word first): 1 absolute run (2 words, pulses), 2 relative run (2 words), 51 start speed, 53 stop speed (1-2000, 0.01 rev/s), 54 run speed (1-5000, 0.01 rev/s), 61 acceleration, 62 deceleration (5-10000 rev/s²), 65 wait and jump (2 words: the instruction to go on at, its high byte 0, then the wait in ms), 66 loop (2 words: how many times the body runs in all, 0 for ever, then the instruction to jump back to), 100 the end of a segment. Segment 1 begins at 1024 and each next one after the previous one's 100; 0327 says how many there are. A jump's address is an instruction's number, counted from 0 at 1024 across the program (256 at most), and must lie in its own segment; a segment holds 8 counted loops at most. Each segment starts at the manual's defaults (start and stop speed 100, run speed 1000, ramps 100), and the next instruction follows a move once the axis stands on its target. The registers read back as written; a write is refused (04) while a program runs or a save is under way, and a request that runs past 1536 with 02.",
        "0323 = 14 checks segments 1 to 0327: 0176 shows the first one in error (an unknown code, a value out of range, a speed the drive cannot run at the resolution in force, a jump outside the segment, no end code before 1536, more than 256 instructions), 0 if none. 16 starts the segment the inputs with functions 25-29 select (0174, 1 + their bits: the manual's table), or else 0328 + 1; it is refused (04) with 0176 set if a segment is in error or the selected one is beyond 0327, and as a run is (04) with the power stage off, an alarm latched, the axis moving or in the pulse following. 17 pauses (the axis stops at the segment's deceleration; 16 resumes the move or the wait it paused), 18 ends the program at the segment's deceleration, and 6, 7, a fault, a disable or a move ending anywhere but on its target (a limit) end it too. While it runs 0178 shows the segment (1-32) and the other motion commands are refused (04). 15 saves the program and the parameters (as 0x200F = 2); so does 0x200F = 2 and 0206 = 1; the program is saved in flash beside the parameters (about 1.4 KB a save, into the one of two banks the last save did not use, then committed: a power cut during a save leaves the old program) and loaded at power-up. The manual's note that function 15 starts a program contradicts its list (16 start, 15 save): the list is followed. The program has a memory of its own beside the PVT point table (PVT points through the native map leave it whole); the native map has no program window, and so no program (0x21A0 = 14-18 refused there, 04).",
        "Timing exceptions (§十三's table): a frame with a silence over 1.5 characters inside it is answered 0C, and a whole frame (its CRC good) that the next bytes followed before 3.5 characters of silence is answered 0D, either once the line has been quiet for 3.5 characters, with the address and function code the frame began with; the bytes in between are dropped and the request is not executed. A frame that did not begin with this drive's address, a broadcast, or one too short to say is not answered. Two frames with less than 1.5 characters between them are one frame with a wrong CRC: not answered, as every frame whose CRC or parity is wrong (its address cannot be trusted).",
    ],
    remarks: &[
        (100, "Motor current: the larger phase current, 0.1 A."),
        (101, "Supply voltage, V."),
        (104, "Resolution in force, pulses a revolution (two words)."),
        (108, "Alarm code (table 1-2), 0 without an alarm."),
        (109, "Run state (table 1-1): 1 enable off, 2 standing, 3 running."),
        (117, "Target position: where the running motion heads (pulses)."),
        (119, "Actual speed, 0.01 rev/s, signed."),
        (126, "Actual position, pulses."),
        (106, "Pulse input format in force: 1 pulse and direction, 2 double pulse."),
        (174, "Segment the inputs select (functions 25-29), 1-32; 0 when no input selects."),
        (176, "First segment in error at the last check or refused start, 0 none."),
        (178, "Running segment (1-32), 0 when no program runs."),
        (201, "Motor direction: 1 turns the motor the other way; from the next power-up (save first)."),
        (206, "User command: 1 parameter reset and save, 2 alarm clear, 3 restart (refused)."),
        (213, "Standstill current, percent of 0241, after 0245."),
        (217, "0 open loop, 1 closed loop; from the next power-up (save first)."),
        (234, "Pulse input filter, 1-15 (12 ns to 1.5 µs)."),
        (241, "Phase current, mA."),
        (242, "Resolution, pulses a revolution (two words)."),
        (244, "Pulse input format: 1 pulse and direction, 2 double pulse."),
        (245, "Standstill delay, ms."),
        (246, "Encoder counts a revolution (lines × 4); from the next power-up."),
        (247, "In-position window, encoder counts (two words)."),
        (258, "Position error threshold, encoder counts: alarm 25 beyond it in closed loop; 0 the drive's 0x605C."),
        (
            296,
            "0 follow the pulse input (external pulses), 1 commanded over the bus; from the next power-up (save first).",
        ),
        (298, "Node id, from the next power-up (save first)."),
        (299, "Baud rate, from the next power-up (save first)."),
        (301, "Start speed, 0.01 rev/s."),
        (302, "Stop speed, 0.01 rev/s."),
        (303, "Acceleration, rev/s²."),
        (304, "Deceleration (also command 6's), rev/s²."),
        (305, "Homing direction: 0 clockwise (negative), 1 counter-clockwise."),
        (306, "Speed of the absolute and relative runs, 0.01 rev/s."),
        (307, "Speed of the velocity run (3), 0.01 rev/s, its sign the direction."),
        (308, "Jog speed, 0.01 rev/s."),
        (309, "Homing search speed, 0.01 rev/s."),
        (310, "Homing creep speed (after the switch is found), 0.01 rev/s."),
        (311, "Homing offset: the position the home reads, pulses."),
        (313, "Target of the absolute run, distance of the relative one, pulses."),
        (317, "Positive soft limit, pulses (0324 bit 0)."),
        (319, "Negative soft limit, pulses (0324 bit 1)."),
        (321, "The position command 8 sets, pulses."),
        (323, "Control command (see the notes)."),
        (324, "Bit 0 the positive soft limit on, bit 1 the negative one."),
        (327, "Program segments, 1-32."),
        (328, "Segment a start runs, 0-31 (segment + 1), unless inputs select one."),
        (400, "IN1 function (see the notes); 0401-0406 IN2-IN7."),
        (410, "Pseudo-input IN1: 1 acts as IN1 turning active; 0411-0416 IN2-IN7."),
        (
            420,
            "OUT1 function: 100 general, 101 alarm, 102 in position, 103 motor free, 104 ready; 0421-0423 OUT2-OUT4.",
        ),
        (428, "General outputs: bit k turns OUT k+1 on (function 100)."),
        (429, "Input logic: bit k set, IN k+1 active low."),
        (430, "Output logic: bit k set, OUT k+1 low when on."),
    ],
    decimal: true,
};
