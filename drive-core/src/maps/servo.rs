//! The servo map (seed 004 §6.3-§6.4): the parameter area 0000h-03FFh (P□abc at register abc,
//! decimal), the alarm history, the monitor block, the communication IO, the jogs and the
//! position data groups, 32-bit values low word first and written whole, Modbus's codes 02-04;
//! framed in Modbus ASCII or RTU as P□600 (0x21F1) says.
//!
//! ```
//! use drive_core::maps::Maps;
//! use drive_core::od::Obj;
//! use drive_core::{Drive, DriveConfig, Instant};
//! let mut drive = Drive::with_map(DriveConfig::default(), Maps::servo());
//! // P□602 (0x025A) = 50: the master must be heard every 5 s.
//! drive.on_rx(Instant::from_micros(0), &[0x01, 0x06, 0x02, 0x5A, 0x00, 0x32, 0x29, 0xB4]);
//! drive.on_timer(Instant::from_micros(4_011));
//! assert!(drive.take_reply().is_some());
//! assert_eq!(drive.state().read(Obj::CommTimeout), 50);
//! ```

use super::compiled::Compiled;
use super::layout::{Choice, Entry, Exceptions, Layout, ProgramWindow, Scale, SpoiltCodes, Walk, WordOrder};
use crate::od::Obj;
use crate::state::ProgramKind;

/// r/min in the drive's microsteps a second.
const RPM: Scale = Scale::PerRev(1, 60);
/// 10 r/min/s in the drive's microsteps a second squared.
const TEN_RPM_S: Scale = Scale::PerRev(1, 6);
/// An alarm history entry's code.
const ALARM: Scale = Scale::Field(24, 8);

/// 0520h: 1 clears the alarm history (0x200F = 5).
static CLEAR_HISTORY: &[Choice] = &[Choice { lo: 1, hi: 1, drive: 5 }];
/// 0521h, 0522h: 1 clears the alarms (0x200F = 4).
static CLEAR_ALARMS: &[Choice] = &[Choice { lo: 1, hi: 1, drive: 4 }];
/// 0540h: 1 restores the factory values and saves them (0x200F = 3).
static FACTORY: &[Choice] = &[Choice { lo: 1, hi: 1, drive: 3 }];

/// 05FAh: 0 the present position is the reference (35); 1 the reference switch searched in the
/// positive direction (19), 2 in the negative one (21); 3 the positive limit switch (18), 4
/// the negative one (17).
static REFERENCE_MODES: &[Choice] = &[
    Choice { lo: 0, hi: 0, drive: 35 },
    Choice { lo: 1, hi: 1, drive: 19 },
    Choice { lo: 2, hi: 2, drive: 21 },
    Choice { lo: 3, hi: 3, drive: 18 },
    Choice { lo: 4, hi: 4, drive: 17 },
];

/// The registers, by address: §6.4's, then ours at their native addresses (the save, the map,
/// the jog distance, the inputs' and outputs' functions).
pub static ENTRIES: [Entry; 82] = [
    Entry::new(0x0130, Obj::JogSpeed, &RPM).narrow(),
    Entry::new(0x01F7, Obj::SpeedWindow, &RPM).narrow(),
    Entry::new(0x0200, Obj::SignalInputs1, &Scale::One),
    Entry::new(0x0201, Obj::SignalInputs2, &Scale::One),
    Entry::new(0x0258, Obj::SerialFormat, &Scale::One),
    Entry::new(0x0259, Obj::NodeId, &Scale::One),
    Entry::new(0x025A, Obj::CommTimeout, &Scale::One),
    Entry::new(0x0400, Obj::FaultHistory0, &ALARM).narrow(),
    Entry::new(0x0401, Obj::FaultHistory1, &ALARM).narrow(),
    Entry::new(0x0402, Obj::FaultHistory2, &ALARM).narrow(),
    Entry::new(0x0403, Obj::FaultHistory3, &ALARM).narrow(),
    Entry::new(0x0404, Obj::FaultHistory4, &ALARM).narrow(),
    Entry::new(0x0405, Obj::FaultHistory5, &ALARM).narrow(),
    Entry::new(0x0406, Obj::FaultHistory6, &ALARM).narrow(),
    Entry::new(0x0407, Obj::FaultHistory7, &ALARM).narrow(),
    Entry::new(0x0408, Obj::FaultHistory8, &ALARM).narrow(),
    Entry::new(0x0409, Obj::FaultHistory9, &ALARM).narrow(),
    Entry::new(0x0420, Obj::RealSpeed, &RPM),
    Entry::new(0x0422, Obj::ElectricalAngle, &Scale::One).wide(),
    Entry::new(0x0424, Obj::PulseRate, &Scale::Ratio(1000, 1)),
    Entry::new(0x0426, Obj::SupplyVoltage, &Scale::Ratio(1000, 1)).wide(),
    Entry::new(0x0428, Obj::AnalogSpeed, &RPM),
    Entry::new(0x042C, Obj::CurrentCommand, &Scale::One).wide(),
    Entry::new(0x042E, Obj::InputStates, &Scale::One).wide(),
    Entry::new(0x0430, Obj::OutputStates, &Scale::One).wide(),
    Entry::new(0x0432, Obj::EncoderSignals, &Scale::One).wide(),
    Entry::new(0x0434, Obj::CommandCount, &Scale::One).read_only(),
    Entry::new(0x0436, Obj::ActualPosition, &Scale::One),
    Entry::new(0x0438, Obj::FollowingError, &Scale::One),
    Entry::new(0x043A, Obj::Load, &Scale::One).wide(),
    Entry::new(0x043E, Obj::EncoderAngle, &Scale::One),
    Entry::new(0x0440, Obj::EncoderTurns, &Scale::One),
    Entry::new(0x044A, Obj::AlarmCode, &Scale::One),
    Entry::new(0x0451, Obj::CommInputs, &Scale::One),
    Entry::new(0x0452, Obj::OutputLogic, &Scale::One),
    Entry::new(0x0457, Obj::RunState, &Scale::One),
    Entry::new(0x045E, Obj::SoftwareRevision, &Scale::One),
    Entry::new(0x045F, Obj::HardwareRevision, &Scale::One),
    Entry::new(0x0520, Obj::SystemControl, &Scale::Table(&CLEAR_HISTORY)),
    Entry::new(0x0521, Obj::SystemControl, &Scale::Table(&CLEAR_ALARMS)),
    Entry::new(0x0522, Obj::SystemControl, &Scale::Table(&CLEAR_ALARMS)),
    Entry::new(0x0528, Obj::SpeedJog, &Scale::One),
    Entry::new(0x0529, Obj::PositionJog, &Scale::One),
    Entry::new(0x0540, Obj::SystemControl, &Scale::Table(&FACTORY)),
    Entry::new(0x0541, Obj::Restart, &Scale::One),
    Entry::new(0x05F0, Obj::GroupRunning, &Scale::One),
    Entry::new(0x05F1, Obj::GroupNext, &Scale::One),
    Entry::new(0x05F2, Obj::ActualPosition, &Scale::Gear),
    Entry::new(0x05F4, Obj::GroupSource, &Scale::One),
    Entry::new(0x05F5, Obj::PpAccel, &TEN_RPM_S).narrow(),
    Entry::new(0x05F6, Obj::PpDecel, &TEN_RPM_S).narrow(),
    Entry::new(0x05F7, Obj::QuickStopDecel, &TEN_RPM_S).narrow(),
    Entry::new(0x05F8, Obj::GearNumerator, &Scale::One),
    Entry::new(0x05F9, Obj::GearDenominator, &Scale::One),
    Entry::new(0x05FA, Obj::HomingMethod, &Scale::Table(&REFERENCE_MODES)),
    Entry::new(0x05FB, Obj::HomingSearchSpeed, &RPM).narrow(),
    Entry::new(0x05FC, Obj::HomingCreepSpeed, &RPM).narrow(),
    Entry::new(0x05FD, Obj::TeachPosition, &Scale::Gear),
    Entry::new(0x200F, Obj::SystemControl, &Scale::One),
    Entry::new(0x2190, Obj::RegisterMap, &Scale::One),
    Entry::new(0x2196, Obj::JogDistance, &Scale::One),
    Entry::new(0x21BA, Obj::InputFunction1, &Scale::One),
    Entry::new(0x21BB, Obj::InputFunction2, &Scale::One),
    Entry::new(0x21BC, Obj::InputFunction3, &Scale::One),
    Entry::new(0x21BD, Obj::InputFunction4, &Scale::One),
    Entry::new(0x21BE, Obj::InputFunction5, &Scale::One),
    Entry::new(0x21BF, Obj::InputFunction6, &Scale::One),
    Entry::new(0x21C0, Obj::InputFunction7, &Scale::One),
    Entry::new(0x21C1, Obj::InputLogic, &Scale::One),
    Entry::new(0x21C3, Obj::OutputFunction1, &Scale::One),
    Entry::new(0x21C4, Obj::OutputFunction2, &Scale::One),
    Entry::new(0x21C5, Obj::OutputFunction3, &Scale::One),
    Entry::new(0x21C6, Obj::OutputFunction4, &Scale::One),
    Entry::new(0x21F2, Obj::SpeedWindow, &Scale::One),
    Entry::new(0x6007, Obj::Mode, &Scale::One),
    Entry::new(0x600C, Obj::Microsteps, &Scale::One),
    Entry::new(0x600D, Obj::PhaseCurrent, &Scale::One),
    Entry::new(0x6011, Obj::Enable, &Scale::One),
    Entry::new(0x6067, Obj::PpAccel, &Scale::One),
    Entry::new(0x6069, Obj::PpDecel, &Scale::One),
    Entry::new(0x606B, Obj::PpStartSpeed, &Scale::One),
    Entry::new(0x606D, Obj::PpStopSpeed, &Scale::One),
];

/// §6.3's codes: 02 no such register, 03 a value out of range, 04 a request the drive cannot
/// carry out now (busy, disabled, faulted, not in this state, the drive does not do it).
pub const EXCEPTIONS: Exceptions = Exceptions::MODBUS;

/// The registers of §6.4 the drive has nothing for (read 0, writes refused with 04): the
/// parameters this excerpt does not describe, the analog zero offsets, the analog torque
/// command, the inertia ratio and the multi-turn clear.
static RESERVED: [(u16, u16); 9] = [
    (0x0000, 0x012F),
    (0x0131, 0x01F6),
    (0x01F8, 0x01FF),
    (0x0202, 0x0257),
    (0x025B, 0x03FF),
    (0x0410, 0x0413),
    (0x042A, 0x042B),
    (0x043C, 0x043D),
    (0x0523, 0x0523),
];

/// The position data groups' window: 32 groups of 8 registers at 0600h.
const GROUPS: ProgramWindow = ProgramWindow {
    first: 0x0600,
    words: crate::state::groups::WORDS as u16,
    kind: ProgramKind::Groups,
    check: Some(crate::state::groups::word_ok),
};

/// How a request walks [`ENTRIES`].
const WALK: Walk = Walk::Address;

/// The servo layout.
pub static LAYOUT: Layout = Layout {
    entries: &ENTRIES,
    order: WordOrder::LowFirst,
    exceptions: EXCEPTIONS,
    walk: WALK,
    halves: false,
    spoilt: SpoiltCodes::DROPPED,
    defaults: &DEFAULTS,
    program: Some(GROUPS),
    reserved: &RESERVED,
    sub_index: None,
    address: None,
    scope: true,
    index: Some(&INDEX),
};

/// The table's compiled lookup.
static INDEX: Compiled = compiled!(ENTRIES, WALK);

/// The manual's factory values where they differ from the drive's: P□503 10 r/min.
static DEFAULTS: [(u16, i32); 1] = [(0x01F7, 10)];

/// What the reference says beside the table: the decisions where seed 004 is silent or
/// contradicts itself.
#[cfg(feature = "docs")]
pub static REFERENCE: super::doc::Reference = super::doc::Reference {
    title: "servo map (seed 004)",
    notes: &[
        "Chosen with 0x2190 = 4, saved (0x200F = 2), from the next power-up; `hal-sim --map servo` for one run. 0x2190 = 0 and a save switch back to the native map. The map powers up with the servo off (the power state machine switch on disabled) until servo-on: 0451h bit 0, 0528h/0529h bit 15, or an input with the enable function.",
        "Framing: P□600 (0258h, the drive's 0x21F1) chooses Modbus RTU or ASCII with the parity and the baud rate; like P□601 it takes effect after a save (0x200F = 2) and a restart (0541h = 1 or a power cycle). ASCII lines are `:`, hex, LRC, CR LF, with the Modbus serial line's 1 s inter-character timeout; a line with a wrong LRC, a wrong character or an odd number of digits is dropped (§6.3: a transmission error is not answered). Broadcast (address 0) is carried out and never answered. A read takes up to 125 registers (the manual's 20 and more); a write up to 123.",
        "Parameters: P□abc is register abc, decimal (P□304 is 0130h, P□600 0258h): the parameter area 0000h-03FFh holds P□000-P□1023. §6.3's exception example writes Pn100 at 0002h, which this numbering does not follow. The parameters it describes act: P□304 (jog speed, r/min), P□503 (speed coincidence window, r/min, factory 10: an output with function 6 is /V-CMP, /COIN in a position move), P□600 (serial format: digit 0 the baud rate 0 4800, 1 9600, 2 19200, 3 38400, 4 57600, 5 115200; digit 1 0-2 RTU 8N1/8E1/8O1, 3-5 ASCII 8N1/8E1/8O1; 7-bit framings are not offered: the drive's line is 8 data bits), P□601 (address 1-127, one axis: A), P□512 and P□513 (the signal allocation §6.4 *1 names in \"P□512.1 = 0\": one hexadecimal digit a signal, 0 not from an input, so that 0451h's bit acts, 1-7 the input IN1-IN7 that carries it; a write gives the input that function and takes it from the others; digits 8-F, which would name terminals the drive does not have, and two signals on one input are refused with 03 — so §6.3's read example, 0200h-0201h = 00B1h 1F40h, shows a state this drive cannot be in, and its write 0200h = 0064h is /START-HOME on IN4 and /POS-START on IN6), P□602 (communication timeout in 100 ms, 0 off: the moving axis decelerates to rest, alarm 30 is recorded and current, moves are refused until 0521h = 1). The others read 0 and refuse writes with 04.",
        "Parameters are kept by a save (0x200F = 2) as in every map, not at each write: a flash write per register would wear the store and stall the bus side while the motor runs.",
        "32-bit values (two registers) are low word first (§6.4: 0600h target low, 0601h high) and written whole with 0x10 (one half alone is refused with 02); the drive's own registers at their native addresses take the same order.",
        "Alarm codes (0400h-0409h, newest first, and 044Ah): the drive's: 10 over-current, 11 phase loss, 13 under-voltage, 14 over-voltage, 15 over-temperature, 25 position error, 26 overload, 27 encoder lost, 30 communication timeout. 0520h = 1 clears the history, 0521h = 1 the current alarms (a cause still present latches again), 0522h = 1 as 0521h (the encoder's alarms are the drive's); 0523h (clear the multi-turn data) is refused with 04: the multi-turn encoder keeps its own turns. 0457h is the run state: 1 the motor not energised (servo off, or an alarm that frees it), 2 energised at rest, 3 moving; the communication timeout stops the axis but keeps the motor energised (2).",
        "Monitors (0420h-0440h, two registers each): 0420h speed r/min; 0422h electrical angle (the commanded microstep in its 4-full-step cycle); 0424h pulse input speed, kHz, while following pulses; 0426h supply V; 0428h analog speed command r/min (0x2170-0x2173); 042Ah (analog torque command) reads 0: the drive has no torque input; 042Ch current command, percent of the phase current 0x600D; 042Eh the inputs IN1-IN7 active (bit k IN k+1; the control tick reads the inputs that have a function, 0x21BA-0x21C0); 0430h the outputs OUT1-OUT4 on; 0432h the encoder's A (bit 0) and B (bit 1); 0434h pulses commanded (0x21D4); 0436h feedback pulses (the actual position); 0438h position error (0x2105); 043Ah load, the measured current in percent of 0x600D; 043Ch (inertia ratio) reads 0: the drive does not identify inertia; 043Eh and 0440h the encoder's angle (microsteps) and turns. 0410h-0413h (analog and current-sense zero offsets) read 0: the drive has no analog speed or torque command offset, and its current sensing is the power stage's.",
        "Communication IO 0451h (not saved): bit 0 /SON (servo on), 2 P-OT and 3 N-OT (1: that overtravel is reached, the axis stops and moves towards it are refused), 4 /ALM-RST (rising edge: 0521h), 5 /CLR (rising edge, at rest: the position error cleared), 9-11 /POS0-2 (the group POS-START runs), 13 /POS-START, 14 /POS-STEP, 15 /START-HOME (rising edges). A bit acts only while no input carries that signal's function (§6.4 *1). Bits 1 (/P-CON), 6-7 (/P-CL, /N-CL), 8 (/G-SEL) are refused (03): the drive has no P/PI switch, external torque limit or second gain set; bit 12 (/POS-REF) is refused: the reference switch must be an input, whose edge the control tick captures. 0452h inverts the outputs (0x21C8, bit k OUT k+1).",
        "Jogs: 0528h bit 15 servo-on for the jog, bit 0 JOG+ (positive), bit 1 JOG- (negative) run at P□304 while set (the manual labels bit 1 \"forward\" and bit 0 \"reverse\" beside the names JOG-/JOG+; the names are followed); clearing bit 15 stops and de-energises once at rest. 0529h bit 15 enters the position jog, and each rising edge of bit 0 / bit 1 moves 0x2196 microsteps positive / negative at P□304. Jog bits without bit 15 are refused (04), as is a jog towards an overtravel.",
        "Position data groups 0600h-06FFh: 32 groups of 8 registers: target (low, high; in the groups' unit: 05F8h/05F9h microsteps), speed r/min (1-6000 for a move), step-change attribute (bits 0-3 condition 1, bits 4-7 condition 2: 0 none, 1 arrival, 2 a time after arrival in ms, 3 an input after arrival, value 1-7 IN1-IN7 or 8-23 bit 0-15 of 0451h; bit 8: either condition, else both), condition 1 and 2 values, next group (0-31), type (0 none, 1 absolute, 2 relative). A value out of range is refused (03). The groups' registers are raw words, written one at a time or together (a target's two halves are taken when the group runs), unlike the objects' 32-bit values. The chain steps on once the move has arrived and its conditions hold; a group with no condition, or whose next group is of type none, ends the chain. Moves ramp at 05F5h/05F6h (the drive's 0x6067/0x6069) from the start and to the stop speed (0x606B/0x606D). POS-START runs the group POS0-2 select (or the inputs with functions 25-27: 05F4h = 1); POS-STEP steps on at once from a group that waits; a stop, an alarm or servo-off ends the chain. 05F0h reads the running group, 05F1h the next (0xFFFF none); groups are saved with the parameters. The running group's registers refuse writes (04).",
        "05F5h-05F7h in 10 r/min/s (the drive's 0x6067, 0x6069, 0x2183). 05FAh reference search: 0 the present position, 1 the reference switch searched positive, 2 negative, 3 the positive limit switch, 4 the negative one (CiA 402 methods 35, 19, 21, 18, 17 of 0x2160), at 05FBh and leaving it at 05FCh (r/min); START-HOME runs it. 05FDh/05FEh teach position: a write names the position the axis stands on (refused while moving), read back as written.",
        "0540h = 1 restores the factory values and saves them; 0541h = 1 restarts the drive once the reply has gone out (refused while moving or saving). Device identification (0x2B) names the map.",
    ],
    remarks: &[
        (0x0130, "P□304 jog speed, r/min."),
        (0x01F7, "P□503 speed coincidence window, r/min."),
        (
            0x0200,
            "P□512 signal allocation: .0 /START-HOME, .1 /POS-START, .2 /POS-STEP, .3 /ALM-RST; each digit 0 (from 0451h) or 1-7 (IN1-IN7).",
        ),
        (0x0201, "P□513 signal allocation: .0 /POS0, .1 /POS1, .2 /POS2, .3 /SON, as P□512."),
        (0x0258, "P□600 serial format (see the notes)."),
        (0x0259, "P□601 address, from the next power-up (save first)."),
        (0x025A, "P□602 communication timeout, 100 ms, 0 off."),
        (0x0000, "Parameters this excerpt does not describe: read 0, writes refused (04)."),
        (0x0410, "Zero offsets: read 0 (see the notes)."),
        (0x042A, "Analog torque command: reads 0, no torque input."),
        (0x043C, "Inertia ratio: reads 0, not identified."),
        (0x0523, "Clear the multi-turn data: refused (04)."),
    ],
    decimal: false,
};
