//! The soak: several simulated drives on one RS-485 bus under seeded random legal traffic from a
//! master, with disturbances, for simulated hours, faster than real time; checked all along.
//!
//! The master ([`run`]) moves the drives (relative and absolute moves, re-targets and speed
//! changes while moving, velocity runs, decelerating and immediate stops, PVT streams refilled on
//! the FIFO's low mark, synchronous moves started by one broadcast and group stops), writes and
//! saves parameters, reads every object and the diagnostic counters. Now and then a request is
//! lost or corrupted on the line, a read's reply is lost (the master repeats both, as a master
//! does after its timeout), the supply dips (staying above the under-voltage threshold), the load
//! steps (within the motor's torque), and the power is cut (during a save, at a random flash
//! operation, or at rest).
//!
//! What it checks, and fails on with the seed and the operation's number:
//! - every reply is well formed (CRC, address, function, length) and answers its request; only
//!   the addressed drive answers, nobody answers a broadcast or a damaged frame;
//! - a request the master sends expecting success succeeds, and reads of the settings it wrote
//!   return what it wrote;
//! - every position move (relative, absolute, re-targeted, synchronous, a PVT stream's last point)
//!   settles exactly on its target, in the drive and in what the master reads;
//! - the encoder agrees with the position within one full step, every millisecond, except after an
//!   immediate stop at speed (which may slip: the check takes the new offset once the motor rests);
//! - no fault, stop, stall, PVT underflow or communication-timeout bit latches;
//! - the diagnostic counters (0x08, 0x0B-0x0F) equal what the master sent, lost and damaged;
//! - after every power cut the store loads the last set saved, or the set whose save the cut
//!   interrupted, never a mix and never unreadable.
//!
//! Everything random comes from one generator seeded with [`Config::seed`]: the same seed and
//! configuration replay the same run exactly (`cargo xtask soak --seed S`).

use std::collections::VecDeque;
use std::fmt;
use std::time::{Duration, Instant as WallClock};

use crate::Drive;
use drive_core::control::TICK_MICROS;
use drive_core::crc::crc16;
use drive_core::drive::{STATUS_BUSY, STORAGE_SAVE_FAILED, STORAGE_SAVING};
use drive_core::od::{Access, OBJECTS, Obj, Storage};
use drive_core::store::Store;
use drive_core::{Baud, DriveConfig, Instant, Params, SlaveAddr};

use crate::bridges::{PowerStage, SensingOptions};
use crate::flash::{PAGES, SimFlash, Tear, block_on};
use crate::inject::Change;
use crate::motor::{Motor, MotorCatalog, MotorInputs, MotorParams};
use crate::plant::Plant;

/// What to soak.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Config {
    /// The seed of every random choice.
    pub seed: u64,
    /// Simulated time to run, µs.
    pub duration_us: u64,
    /// Drives on the bus (addresses 1..=axes), each with its own motor and flash.
    pub axes: u8,
    /// Print a line of figures to stderr every this many simulated seconds (0: never).
    pub progress_s: u64,
    /// Print every operation to stderr as it is done.
    pub trace: bool,
    /// How the drives' windings are driven (each drive's ADC noise seeded by its address).
    pub power_stage: PowerStage,
}

/// What a soak did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Report {
    /// Simulated time, µs.
    pub simulated_us: u64,
    /// Operations of the master.
    pub operations: u64,
    /// Request frames put on the line (damaged ones included, lost ones not).
    pub frames: u64,
    /// Replies received and checked.
    pub replies: u64,
    /// Requests lost on the line, requests damaged on it, and replies lost.
    pub lost: u64,
    /// See [`Report::lost`].
    pub corrupted: u64,
    /// See [`Report::lost`].
    pub lost_replies: u64,
    /// Position moves that settled, each checked exactly on its target.
    pub moves: u64,
    /// Re-targets and speed changes of running moves.
    pub retargets: u64,
    /// Velocity runs.
    pub velocity_runs: u64,
    /// Immediate stops (0x6053) and decelerating group stops (0x2114).
    pub stops: u64,
    /// PVT streams run to their end, and the points pushed for them.
    pub pvt_streams: u64,
    /// See [`Report::pvt_streams`].
    pub pvt_points: u64,
    /// Synchronous moves started by a broadcast.
    pub group_starts: u64,
    /// Parameter saves that completed, and power cuts (with a restart from the flash).
    pub saves: u64,
    /// See [`Report::saves`].
    pub power_cuts: u64,
    /// Diagnostic counter checks.
    pub counter_checks: u64,
    /// Supply dips and load steps.
    pub disturbances: u64,
    /// Wall time the run took.
    pub wall: Duration,
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let h = self.simulated_us as f64 / 3.6e9;
        write!(
            f,
            "{h:.3} simulated hours in {:.1} s of wall time ({:.0}x): {} operations, {} frames ({} lost, {} damaged, {} replies lost), {} replies; {} moves settled on target, {} re-targets and speed changes, {} velocity runs, {} stops, {} PVT streams ({} points), {} group starts, {} saves, {} power cuts, {} counter checks, {} disturbances",
            self.wall.as_secs_f64(),
            self.simulated_us as f64 / 1e6 / self.wall.as_secs_f64().max(1e-9),
            self.operations,
            self.frames,
            self.lost,
            self.corrupted,
            self.lost_replies,
            self.replies,
            self.moves,
            self.retargets,
            self.velocity_runs,
            self.stops,
            self.pvt_streams,
            self.pvt_points,
            self.group_starts,
            self.saves,
            self.power_cuts,
            self.counter_checks,
            self.disturbances,
        )
    }
}

/// A check that failed: where, and how to replay it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Failure {
    /// The run's seed.
    pub seed: u64,
    /// The number of the operation that failed (from 1).
    pub operation: u64,
    /// Simulated time, µs.
    pub at_us: u64,
    /// What failed.
    pub message: String,
    /// The last operations before it, oldest first.
    pub recent: Vec<String>,
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "soak failed: seed {}, operation {}, at {:.6} s: {}",
            self.seed,
            self.operation,
            self.at_us as f64 / 1e6,
            self.message
        )?;
        writeln!(f, "the operations before it:")?;
        for r in &self.recent {
            writeln!(f, "  {r}")?;
        }
        write!(f, "replay: cargo xtask soak --seed {} (with the same --minutes/--hours and --axes)", self.seed)
    }
}

/// Baud rate of the soak's bus: the fastest the drive takes, for the most traffic a second.
const BAUD: u32 = 115_200;
/// One character on the line (11 bits at 115 200 bit/s), rounded up, µs.
const CHAR_US: u64 = 96;
/// How long the master waits for a reply that does not come, µs.
const TIMEOUT_US: u64 = 20_000;
/// The longest the master leaves a drive unaddressed, µs (its communication timeout: 30 s).
const KEEPALIVE_US: u64 = 5_000_000;
/// How often the continuous checks run, µs.
const CHECK_US: u64 = 1_000;
/// Checks in a row the rotor must stand still before the encoder check takes its offset.
const STILL_CHECKS: u32 = 100;
/// Microstep resolutions the drives are set to (one each, round robin).
const RESOLUTIONS: [u16; 3] = [16, 8, 32];
/// Phase current, mA: with the standstill reduction down to half it still holds the load steps.
const CURRENT_MA: u16 = 1500;
/// The fastest the master runs a motor, full steps a second (4 rev/s).
const FULL_STEPS_PER_S_MAX: f64 = 800.0;
/// The slowest speed the master sets, as a share of the fastest.
const SLOWEST: f64 = 0.05;
/// The farthest from 0 the master sends a motor, full steps.
const FULL_STEPS_SPAN: i64 = 40_000;
/// The largest load torque, N·m: a sixth of the torque of 1.5 A, a third at half of it (the
/// lowest standstill current the master sets).
const LOAD_MAX_NM: f64 = 0.05;
/// The PVT FIFO's depth and marks of a stream.
const FIFO: [u16; 3] = [200, 60, 150];

/// The line's time a pushed point takes (request, reply, turnaround, two t3.5), ms, at most.
const PUSH_MS: f64 = 6.0;
/// The share of the line the PVT streams together may take.
const STREAM_LOAD: f64 = 0.5;

/// Points pushed to one stream before the master looks after the other streams: a fill of one
/// axis must not let another's FIFO run dry.
const PUSH_BURST: usize = 24;

/// Settings the master changes (ROM objects that act on motion, the power stage, the outputs
/// or the pulse input), with the values it picks from (inclusive).
const SETTINGS: [(Obj, u32, u32); 15] = [
    (Obj::JerkTime, 10, 300),
    (Obj::PulseFormat, 1, 3),
    (Obj::PulseFilter, 1, 15),
    (Obj::OutputFunction1, 0, 5),
    (Obj::OutputFunction4, 0, 5),
    (Obj::OutputLogic, 0, 15),
    (Obj::InPositionWindow, 0, 1000),
    (Obj::IdleCurrent, 50, 100),
    (Obj::IdleDelay, 100, 2000),
    (Obj::StartSpeed, 100, 600),
    (Obj::StopSpeed, 100, 600),
    (Obj::AccelLevel, 1, 8),
    (Obj::DecelLevel, 1, 8),
    (Obj::CurrentDecay, 2, 3),
    (Obj::PpAccel, 151, 200_000),
];

/// What an axis is doing, as the master knows it.
#[derive(Clone, Debug, PartialEq)]
enum Motion {
    /// At rest in position mode (0x6007 = 0).
    Rest,
    /// A position move (mode 0) that must settle exactly on this target; `None` for a move
    /// whose end the master does not know (a group stop).
    Move(Option<i64>),
    /// A velocity run (mode 1) at this speed, pps, until this simulated time.
    Velocity { speed: i32, until: u64 },
    /// A velocity run decelerating to rest after speed 0 was written.
    Stopping,
    /// A PVT stream (mode 2, FIFO).
    Stream(Stream),
}

/// A PVT stream: its points, how many were pushed, and when the master looks at the FIFO next.
#[derive(Clone, Debug, PartialEq)]
struct Stream {
    points: Vec<(i32, i32, u16)>,
    pushed: usize,
    started: bool,
    /// Below the low mark at the last look: refilled a burst at a time up to the high mark.
    filling: bool,
    /// A group stop ended it before its last point: it ends wherever the stop brought it.
    stopped: bool,
    next_look: u64,
}

/// The diagnostic counters the master expects of a drive.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Counts {
    bus: u16,
    errors: u16,
    exceptions: u16,
    slave: u16,
    no_response: u16,
}

/// One drive on the bus, with what the master knows of it.
struct Axis {
    addr: u8,
    plant: Plant,
    store: Store<SimFlash>,
    /// Microsteps per full step.
    ustep: u32,
    /// The saved objects as the master wrote them, and as the last complete save left them.
    rom: Params,
    saved: Params,
    counts: Counts,
    /// The maximum speed 0x6003 as last written.
    max_speed: i32,
    motion: Motion,
    /// The encoder count and the position when the encoder check took its offset; `None`: take
    /// it when the axis next rests.
    base: Option<(u32, i64)>,
    /// Consecutive checks the rotor stood still at rest, towards taking the offset.
    still_ms: u32,
    /// When the drive last heard a frame addressed to it (or broadcast), µs.
    heard: u64,
    /// Disturbances still to come: (time, change).
    pending: Vec<(u64, Change)>,
}

/// The soak in progress.
struct Soak {
    cfg: Config,
    rng: fastrand::Rng,
    motor: MotorParams,
    axes: Vec<Axis>,
    now: u64,
    t35: u64,
    report: Report,
    recent: VecDeque<String>,
    /// Replies the drives made, with the address of who made them.
    replies: Vec<(u8, Vec<u8>)>,
    /// Simulated time of the next progress line, µs.
    next_progress: u64,
    /// When the run began, for the progress lines.
    began: WallClock,
}

/// Runs a soak; the report, or the first check that failed.
pub fn run(cfg: &Config) -> Result<Report, Box<Failure>> {
    let began = WallClock::now();
    let mut soak = Soak::new(cfg.clone())
        .map_err(|m| Box::new(Failure { seed: cfg.seed, operation: 0, at_us: 0, message: m, recent: Vec::new() }))?;
    let result = soak.main();
    soak.report.simulated_us = soak.now;
    soak.report.wall = began.elapsed();
    match result {
        Ok(()) => Ok(soak.report),
        Err(message) => Err(Box::new(Failure {
            seed: cfg.seed,
            operation: soak.report.operations,
            at_us: soak.now,
            message,
            recent: soak.recent.into_iter().collect(),
        })),
    }
}

type Check = Result<(), String>;

impl Soak {
    fn new(cfg: Config) -> Result<Self, String> {
        let motor = MotorCatalog::builtin().get(crate::DEFAULT_MOTOR).cloned().ok_or("no default motor")?;
        let t35 = Baud::new(BAUD).ok_or("baud")?.t35_micros();
        let mut soak = Soak {
            rng: fastrand::Rng::with_seed(cfg.seed),
            motor,
            axes: Vec::new(),
            now: 0,
            t35,
            report: Report::default(),
            recent: VecDeque::new(),
            replies: Vec::new(),
            next_progress: cfg.progress_s * 1_000_000,
            began: WallClock::now(),
            cfg,
        };
        for addr in 1..=soak.cfg.axes.max(1) {
            let store = crate::store(SimFlash::erased(PAGES)).map_err(|e| e.to_string())?;
            let mut axis = Axis {
                addr,
                plant: Plant::new(
                    Drive::with_map(DriveConfig::default(), drive_core::maps::Maps::by_id(0)),
                    Motor::new(soak.motor.clone(), MotorInputs::default()),
                ),
                store,
                ustep: 1,
                rom: Params::factory(),
                saved: Params::factory(),
                counts: Counts::default(),
                max_speed: 0,
                motion: Motion::Rest,
                heard: 0,
                base: None,
                still_ms: 0,
                pending: Vec::new(),
            };
            let (plant, loaded) = soak.boot(&mut axis.store, addr);
            axis.plant = plant;
            // The boot configuration (address, baud) is part of what the drive holds and saves;
            // what it holds also has the power-up tune's results.
            axis.rom = axis.plant.drive().state().params();
            axis.saved = loaded;
            soak.axes.push(axis);
        }
        Ok(soak)
    }

    /// A drive powered up on `store`, with a new motor at rest, and the objects as it loaded
    /// them (before a power-up tune of its bridges writes what it measured into them).
    fn boot(&self, store: &mut Store<SimFlash>, addr: u8) -> (Plant, Params) {
        let config =
            DriveConfig { address: SlaveAddr::new(addr), baud: Baud::new(BAUD), can_save: true, ..Default::default() };
        let drive = crate::boot(store, config, false, None);
        let loaded = drive.state().params();
        let mut plant = Plant::new(drive, Motor::new(self.motor.clone(), MotorInputs::default()));
        let sensing = SensingOptions { seed: u64::from(addr), ..SensingOptions::default() };
        plant.set_power_stage(self.cfg.power_stage, sensing);
        // The plant's clock starts at the bus's time.
        plant.start_at(Instant::from_micros(self.now));
        (plant, loaded)
    }

    fn main(&mut self) -> Check {
        for i in 0..self.axes.len() {
            self.setup(i)?;
        }
        while self.now < self.cfg.duration_us {
            self.report.operations += 1;
            self.service_streams()?;
            self.operation()?;
            if self.cfg.progress_s > 0 && self.now >= self.next_progress {
                self.next_progress += self.cfg.progress_s * 1_000_000;
                eprintln!("soak: {}", self.report_now());
            }
        }
        // Let every motion end, and check it.
        for i in 0..self.axes.len() {
            self.finish(i)?;
        }
        for i in 0..self.axes.len() {
            self.check_counters(i)?;
        }
        Ok(())
    }

    fn report_now(&self) -> Report {
        Report { simulated_us: self.now, wall: self.began.elapsed(), ..self.report.clone() }
    }

    /// Notes an operation for the failure report.
    fn note(&mut self, what: String) {
        if self.cfg.trace {
            eprintln!("#{} {:.6} s: {what}", self.report.operations, self.now as f64 / 1e6);
        }
        if self.recent.len() == 24 {
            self.recent.pop_front();
        }
        self.recent.push_back(format!("#{} {:.6} s: {what}", self.report.operations, self.now as f64 / 1e6));
    }

    // --------------------------------------------------------------------------------------------
    // The line and the clock.

    /// Runs every drive and motor to `to`, ending frames at their deadlines and checking the
    /// drives every millisecond.
    fn advance(&mut self, to: u64) -> Check {
        while self.now < to {
            let end = (self.now + CHECK_US).min(to);
            for i in 0..self.axes.len() {
                let axis = &mut self.axes[i];
                while let Some(d) = axis.plant.drive().deadline().filter(|d| d.as_micros() <= end) {
                    axis.plant.advance_to(d);
                    axis.plant.drive_mut().on_timer(d);
                    if let Some(r) = axis.plant.drive_mut().take_reply() {
                        self.replies.push((axis.addr, r.to_vec()));
                    }
                }
                while let Some(k) = axis.pending.iter().position(|(t, _)| *t <= end) {
                    let (_, change) = axis.pending.swap_remove(k);
                    axis.plant.inject(change);
                }
                axis.plant.advance_to(Instant::from_micros(end));
            }
            self.now = end;
            for i in 0..self.axes.len() {
                self.watch(i)?;
            }
        }
        Ok(())
    }

    /// The continuous checks of axis `i`: no fault latched, the encoder with the position.
    fn watch(&mut self, i: usize) -> Check {
        let axis = &mut self.axes[i];
        let state = axis.plant.drive().state();
        for (obj, mask) in [
            (Obj::ErrorStatus, 0xFF),
            (Obj::DriveFaults, 0xFF),
            (Obj::CommStatus, 0xFF),
            (Obj::PvtFault, 0xFF),
            // External stops and stall; busy and the FIFO bits are the master's business.
            (Obj::ControllerStatus, 0x17),
            (Obj::AlarmCode, 0xFF),
        ] {
            let v = state.read(obj) & mask;
            if v != 0 {
                return Err(format!("axis {}: {obj:?} = {v:#04X}", axis.addr));
            }
        }
        let Some(out) = axis.plant.outputs() else { return Ok(()) };
        let Some(count) = axis.plant.encoder().reading(axis.plant.motor(), 0) else {
            return Err(format!("axis {}: no encoder reading", axis.addr));
        };
        let counts_per_step =
            f64::from(axis.plant.encoder().kind().counts_per_turn()) / f64::from(self.motor.steps_per_rev);
        match axis.base {
            Some((c0, p0)) => {
                let measured = f64::from(count.wrapping_sub(c0) as i32) / counts_per_step;
                let commanded =
                    ((out.setpoint.whole - p0) as f64 + out.setpoint.fraction.to_num::<f64>()) / f64::from(axis.ustep);
                if (measured - commanded).abs() > 1.0 {
                    return Err(format!(
                        "axis {}: the encoder says {measured:.3} full steps moved, the position {commanded:.3} (motion {:?}, speed {:.0} pps)",
                        axis.addr, axis.motion, out.setpoint.velocity
                    ));
                }
            }
            None => {
                // The offset is taken at rest once the rotor has stood still for 100 ms: a rotor
                // still ringing passes through zero speed at the ends of its swings.
                let resting = axis.motion == Motion::Rest && state.read(Obj::ControllerStatus) as u8 & STATUS_BUSY == 0;
                let still = resting && axis.plant.motor().speed_rps().abs() < 1e-3;
                axis.still_ms = if still { axis.still_ms + 1 } else { 0 };
                if axis.still_ms >= STILL_CHECKS {
                    axis.base = Some((count, out.setpoint.whole));
                }
            }
        }
        Ok(())
    }

    /// Sends `pdu` to `to` (0: broadcast) as the master does: repeated after a timeout when the
    /// request or a read's reply is lost or damaged. The reply's PDU, checked against the request;
    /// `None` for a broadcast.
    fn request(&mut self, to: u8, pdu: &[u8]) -> Result<Option<Vec<u8>>, String> {
        let mut frame = Vec::with_capacity(pdu.len() + 3);
        frame.push(to);
        frame.extend_from_slice(pdu);
        frame.extend_from_slice(&crc16(&frame).to_le_bytes());
        let read_only = matches!(pdu.first(), Some(0x03 | 0x04 | 0x2B)) || is_counter_read(pdu);
        for attempt in 0..4 {
            let end = self.now + frame.len() as u64 * CHAR_US;
            self.advance(end)?;
            let roll = if attempt < 3 { self.rng.u32(0..1000) } else { 999 };
            if roll < 2 {
                // Lost: nobody hears anything.
                self.report.lost += 1;
                self.advance(end + TIMEOUT_US)?;
                continue;
            }
            self.report.frames += 1;
            if roll < 5 {
                // One bit flipped on the line: every drive counts a bad frame and stays silent.
                let mut bad = frame.clone();
                let k = self.rng.usize(0..bad.len());
                bad[k] ^= 1 << self.rng.u8(0..8);
                self.deliver(&bad);
                self.report.corrupted += 1;
                for a in &mut self.axes {
                    a.counts.errors = a.counts.errors.wrapping_add(1);
                }
                self.advance(end + TIMEOUT_US)?;
                if let Some((from, r)) = self.replies.pop() {
                    return Err(format!("axis {from} answered a damaged frame {bad:02X?}: {r:02X?}"));
                }
                continue;
            }
            self.deliver(&frame);
            for a in &mut self.axes {
                a.counts.bus = a.counts.bus.wrapping_add(1);
                if to == 0 || to == a.addr {
                    a.counts.slave = a.counts.slave.wrapping_add(1);
                    a.heard = self.now;
                }
                if to == 0 {
                    a.counts.no_response = a.counts.no_response.wrapping_add(1);
                }
            }
            self.advance(end + self.t35 + 1)?;
            let replies = std::mem::take(&mut self.replies);
            if to == 0 {
                if let Some((from, r)) = replies.first() {
                    return Err(format!("axis {from} answered a broadcast {frame:02X?}: {r:02X?}"));
                }
                // The master leaves the drives time to act on a broadcast.
                let gap = self.rng.u64(2_000..5_000);
                self.advance(self.now + gap)?;
                return Ok(None);
            }
            let mut reply = None;
            for (from, r) in replies {
                if from != to || reply.is_some() {
                    return Err(format!("axis {from} answered {frame:02X?} meant for {to}: {r:02X?}"));
                }
                reply = Some(r);
            }
            let Some(reply) = reply else {
                return Err(format!("axis {to} did not answer {frame:02X?}"));
            };
            check_reply(&frame, &reply)?;
            self.report.replies += 1;
            if reply[1] & 0x80 != 0
                && let Some(a) = self.axes.iter_mut().find(|a| a.addr == to)
            {
                a.counts.exceptions = a.counts.exceptions.wrapping_add(1);
            }
            let turnaround = self.rng.u64(200..2_000);
            self.advance(self.now + reply.len() as u64 * CHAR_US + turnaround)?;
            if read_only && attempt < 3 && self.rng.u32(0..1000) < 2 {
                // The reply was lost: the master times out and asks again.
                self.report.lost_replies += 1;
                self.advance(self.now + TIMEOUT_US)?;
                continue;
            }
            return Ok(Some(reply[1..reply.len() - 2].to_vec()));
        }
        Err(format!("no answer to {frame:02X?} in four attempts"))
    }

    /// Bytes on the bus now: every drive receives them.
    fn deliver(&mut self, bytes: &[u8]) {
        let now = Instant::from_micros(self.now);
        for a in &mut self.axes {
            a.plant.drive_mut().on_rx(now, bytes);
        }
    }

    fn addr(&self, i: usize) -> u8 {
        self.axes[i].addr
    }

    /// Reads `qty` registers at `reg` of axis `i`.
    fn read(&mut self, i: usize, reg: u16, qty: u16) -> Result<Vec<u16>, String> {
        let mut pdu = vec![0x03];
        pdu.extend(reg.to_be_bytes());
        pdu.extend(qty.to_be_bytes());
        let to = self.addr(i);
        let r = self.request(to, &pdu)?.ok_or("no reply")?;
        if r[0] != 0x03 {
            return Err(format!("axis {to}: read of {qty} at {reg:#06X} refused: {r:02X?}"));
        }
        Ok(r[2..].chunks_exact(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect())
    }

    /// Writes `words` at `reg` of axis `i` (0x06 for one word, 0x10 otherwise, or by broadcast
    /// with `i` = `None`); the exception code if refused.
    fn write_to(&mut self, to: u8, reg: u16, words: &[u16]) -> Result<Result<(), u8>, String> {
        let mut pdu = Vec::new();
        if words.len() == 1 && self.rng.bool() {
            pdu.push(0x06);
            pdu.extend(reg.to_be_bytes());
            pdu.extend(words[0].to_be_bytes());
        } else {
            pdu.push(0x10);
            pdu.extend(reg.to_be_bytes());
            pdu.extend((words.len() as u16).to_be_bytes());
            pdu.push(2 * words.len() as u8);
            for w in words {
                pdu.extend(w.to_be_bytes());
            }
        }
        match self.request(to, &pdu)? {
            None => Ok(Ok(())),
            Some(r) if r[0] & 0x80 != 0 => Ok(Err(r[1])),
            Some(_) => Ok(Ok(())),
        }
    }

    /// Writes `words` at `reg` of axis `i`, which must accept them.
    fn write(&mut self, i: usize, reg: u16, words: &[u16]) -> Check {
        let to = self.addr(i);
        match self.write_to(to, reg, words)? {
            Ok(()) => Ok(()),
            Err(code) => Err(format!("axis {to}: write {words:04X?} at {reg:#06X} refused with {code:02X}")),
        }
    }

    /// Writes the maximum speed 0x6003 of axis `i`.
    fn write_speed(&mut self, i: usize, speed: i32) -> Check {
        self.write(i, Obj::MaxSpeed.def().addr, &words32(speed))?;
        self.axes[i].max_speed = speed;
        Ok(())
    }

    /// Writes a 32-bit value (high word first) at `reg` of axis `i`.
    fn write32(&mut self, i: usize, reg: u16, v: i32) -> Check {
        self.write(i, reg, &words32(v))
    }

    /// Lets `us` of simulated time pass, looking after the PVT streams meanwhile and polling the
    /// status of a drive not addressed for [`KEEPALIVE_US`], as a PLC's cyclic poll does (the
    /// drives' communication watchdog is on).
    fn wait(&mut self, us: u64) -> Check {
        let end = self.now + us;
        while self.now < end {
            let step = (end - self.now).min(100_000);
            self.advance(self.now + step)?;
            self.service_streams()?;
            for k in 0..self.axes.len() {
                if self.now - self.axes[k].heard > KEEPALIVE_US {
                    self.read(k, Obj::ControllerStatus.def().addr, 1)?;
                }
            }
        }
        Ok(())
    }

    // --------------------------------------------------------------------------------------------
    // Set-up, settling, power.

    /// Sets axis `i` up: resolution, current, the communication watchdog, settings; saves them.
    fn setup(&mut self, i: usize) -> Check {
        let resolution = RESOLUTIONS[i % RESOLUTIONS.len()];
        self.axes[i].ustep = u32::from(resolution);
        self.set(i, Obj::Microsteps, u32::from(resolution))?;
        self.set(i, Obj::PhaseCurrent, u32::from(CURRENT_MA))?;
        // 30 s: the master addresses every drive far more often; an expiry is a failure.
        self.set(i, Obj::CommTimeout, 300)?;
        self.set(i, Obj::GroupId, 0)?;
        self.save(i)?;
        self.axes[i].base = None;
        self.settle(i)
    }

    /// Writes the setting `obj` = `v` of axis `i` and keeps it in the master's copy.
    fn set(&mut self, i: usize, obj: Obj, v: u32) -> Check {
        let d = obj.def();
        let words: Vec<u16> = if d.words() == 2 { vec![(v >> 16) as u16, v as u16] } else { vec![v as u16] };
        self.write(i, d.addr, &words)?;
        if d.storage() == Storage::Rom {
            self.axes[i].rom.set(obj, v);
        }
        Ok(())
    }

    /// Saves the parameters of axis `i` (at rest), and checks the save ended well.
    fn save(&mut self, i: usize) -> Check {
        self.write(i, Obj::SystemControl.def().addr, &[2])?;
        let failed = self.serve_store(i);
        if let Some(e) = failed {
            return Err(format!("axis {}: save failed: {e}", self.addr(i)));
        }
        let storage = self.read(i, Obj::StorageStatus.def().addr, 1)?[0];
        if storage & u16::from(STORAGE_SAVING | STORAGE_SAVE_FAILED) != 0 {
            return Err(format!("axis {}: storage status {storage:#04X} after a save", self.addr(i)));
        }
        let axis = &mut self.axes[i];
        axis.saved = axis.rom.clone();
        self.report.saves += 1;
        Ok(())
    }

    /// Does what the drive of axis `i` asks of its platform; the error of a failed operation.
    fn serve_store(&mut self, i: usize) -> Option<String> {
        let axis = &mut self.axes[i];
        let mut failed = None;
        while let Some((request, done)) = block_on(axis.store.serve(axis.plant.drive_mut())) {
            if let Err(e) = done {
                failed = Some(format!("{request:?}: {e:?}"));
            }
        }
        failed
    }

    /// Waits until axis `i` rests, and checks it rests where it must.
    fn settle(&mut self, i: usize) -> Check {
        let began = self.now;
        let mut limit = None;
        loop {
            let regs = self.read(i, 0x6000, 16)?;
            let busy = regs[1] & 0x08 != 0;
            let position = i64::from(((u32::from(regs[14]) << 16) | u32::from(regs[15])) as i32);
            if !busy {
                let axis = &mut self.axes[i];
                let addr = axis.addr;
                let drive_position = axis.plant.drive().state().position();
                if drive_position != position {
                    return Err(format!("axis {addr}: reads position {position}, the drive holds {drive_position}"));
                }
                match std::mem::replace(&mut axis.motion, Motion::Rest) {
                    Motion::Move(Some(target)) => {
                        if position != target {
                            return Err(format!("axis {addr}: settled on {position}, not on its target {target}"));
                        }
                        self.report.moves += 1;
                    }
                    Motion::Stream(s) => {
                        let last = s.points.last().map_or(0, |p| p.0);
                        if !s.stopped && i64::from(last) != position {
                            return Err(format!("axis {addr}: the stream ended on {position}, not on {last}"));
                        }
                        self.report.moves += u64::from(!s.stopped);
                        self.report.pvt_streams += 1;
                        self.write(i, Obj::PvtMode.def().addr, &[0])?;
                        self.write(i, Obj::Mode.def().addr, &[0])?;
                    }
                    Motion::Velocity { .. } | Motion::Stopping => {
                        self.write(i, Obj::Mode.def().addr, &[0])?;
                    }
                    Motion::Move(None) | Motion::Rest => {}
                }
                return Ok(());
            }
            // 120 s, plus the time from where the axis was to the target at the slowest speed
            // the master sets.
            let limit = *limit.get_or_insert_with(|| {
                let far = match self.axes[i].motion {
                    Motion::Move(Some(target)) => (target - position).unsigned_abs() as f64,
                    _ => 0.0,
                };
                let slowest = SLOWEST * FULL_STEPS_PER_S_MAX * f64::from(self.axes[i].ustep);
                120_000_000 + (far / slowest * 1e6) as u64
            });
            if self.now - began > limit {
                return Err(format!(
                    "axis {}: still busy after {} s ({:?})",
                    self.addr(i),
                    limit / 1_000_000,
                    self.axes[i].motion
                ));
            }
            let poll = self.rng.u64(10_000..100_000);
            self.wait(poll)?;
        }
    }

    /// Brings axis `i` to rest at the end of the run: ends a velocity run, lets a stream run out.
    fn finish(&mut self, i: usize) -> Check {
        if matches!(self.axes[i].motion, Motion::Velocity { .. }) {
            self.stop_velocity(i)?;
        }
        let mut last = None;
        while let Motion::Stream(s) = &self.axes[i].motion {
            if s.stopped || s.pushed == s.points.len() {
                break;
            }
            // A running stream takes a point at least every 40 ms: 10 s without one is a stall.
            let state = self.axes[i].plant.drive().state();
            let now = (s.pushed, state.read(Obj::PvtCount), state.position());
            if last.is_some_and(|(then, at)| then == now && self.now - at > 10_000_000) {
                let busy = state.read(Obj::ControllerStatus) as u8 & STATUS_BUSY != 0;
                let mode = state.read(Obj::Mode);
                return Err(format!(
                    "axis {}: PVT stream stalled: {} of {} points pushed, {} queued, mode {mode}, busy {busy}",
                    self.addr(i),
                    now.0,
                    s.points.len(),
                    now.1
                ));
            }
            if last.is_none_or(|(then, _)| then != now) {
                last = Some((now, self.now));
            }
            self.wait(100_000)?;
        }
        self.settle(i)
    }

    /// Cuts the power of axis `i` (at rest): during a save at a random flash operation, or at
    /// rest; then it restarts from its flash, which must hold the last complete set or the one
    /// being saved.
    fn power_cut(&mut self, i: usize) -> Check {
        let during_save = self.rng.bool();
        let addr = self.addr(i);
        let mut pending = None;
        if during_save {
            let ops = self.rng.u64(0..48);
            let tear = Tear::ALL[self.rng.usize(0..Tear::ALL.len())];
            self.axes[i].store.flash().cut_after(ops, tear);
            self.note(format!("axis {addr}: power cut after {ops} flash operations of a save ({tear:?})"));
            self.write(i, Obj::SystemControl.def().addr, &[2])?;
            // A cut save fails; one with fewer operations than the cut completes first.
            let _ = self.serve_store(i);
            pending = Some(self.axes[i].rom.clone());
        } else {
            self.note(format!("axis {addr}: power cut at rest"));
        }
        let bytes = self.axes[i].store.flash().bytes().to_vec();
        let mut store = crate::store(SimFlash::from_bytes(bytes)).map_err(|e| e.to_string())?;
        let (plant, loaded) = self.boot(&mut store, addr);
        let state = plant.drive().state();
        let storage = state.read(Obj::StorageStatus);
        let axis = &mut self.axes[i];
        if storage != 0 {
            return Err(format!("axis {addr}: storage status {storage:#04X} after the power cut"));
        }
        if pending.as_ref() == Some(&loaded) {
            axis.saved = loaded;
        } else if loaded != axis.saved {
            let differ: Vec<String> = OBJECTS
                .iter()
                .filter(|d| loaded.get(d.obj) != axis.saved.get(d.obj))
                .map(|d| format!("{:?} {} (saved {})", d.obj, loaded.get(d.obj), axis.saved.get(d.obj)))
                .collect();
            return Err(format!(
                "axis {addr}: after the power cut the store loaded neither the saved set nor the new one: {}",
                differ.join(", ")
            ));
        }
        axis.rom = plant.drive().state().params();
        axis.store = store;
        axis.plant = plant;
        axis.counts = Counts::default();
        axis.max_speed = 0;
        axis.motion = Motion::Rest;
        axis.heard = self.now;
        axis.base = None;
        axis.pending.clear();
        self.report.power_cuts += 1;
        // The restarted drive holds what was saved: the resolution and current among it.
        self.settle(i)
    }

    // --------------------------------------------------------------------------------------------
    // Operations.

    /// One random operation of the master.
    fn operation(&mut self) -> Check {
        let i = self.rng.usize(0..self.axes.len());
        let addr = self.addr(i);
        // A velocity run whose time is up is stopped first.
        if let Motion::Velocity { until, .. } = self.axes[i].motion
            && self.now >= until
        {
            self.note(format!("axis {addr}: velocity run ends"));
            return self.stop_velocity(i);
        }
        let roll = self.rng.u32(0..1000);
        let motion = self.axes[i].motion.clone();
        match (roll, &motion) {
            (0..=229, _) => self.read_objects(i),
            (230..=279, _) => self.diagnostics(i),
            (280..=289, _) => self.device_id(i),
            (290..=359, _) => self.change_setting(i),
            (360..=379, Motion::Rest) => self.save_op(i),
            (380..=382, Motion::Rest) => self.power_cut(i),
            (383..=399, _) => self.disturb(i),
            (400..=449, Motion::Rest) | (400..=419, Motion::Move(Some(_))) => self.relative_move(i),
            (450..=489, Motion::Rest) | (420..=489, Motion::Move(Some(_))) => self.absolute_move(i),
            (490..=539, Motion::Move(Some(_))) => self.change_speed(i),
            (490..=539, Motion::Velocity { .. }) => self.change_velocity(i),
            (540..=579, Motion::Rest) => self.velocity_run(i),
            (580..=589, Motion::Velocity { .. }) => self.stop_velocity(i),
            (580..=599, Motion::Move(Some(_)) | Motion::Velocity { .. }) => self.immediate_stop(i),
            (600..=619, Motion::Rest) => self.pvt_stream(i),
            (620..=649, Motion::Rest) => self.group_start(),
            (650..=659, Motion::Move(_)) => self.group_stop(i),
            (_, Motion::Move(_) | Motion::Stopping) if roll >= 900 => self.settle(i),
            _ => {
                let us = self.rng.u64(1_000..300_000);
                self.wait(us)
            }
        }
    }

    /// Reads a run of objects of one page (0x03 or 0x04) and checks the settings among them.
    fn read_objects(&mut self, i: usize) -> Check {
        let first = self.rng.usize(0..OBJECTS.len());
        let start = &OBJECTS[first];
        let page = start.addr >> 8;
        let mut last = first;
        let more = self.rng.usize(0..12);
        while last + 1 < OBJECTS.len()
            && last - first < more
            && OBJECTS[last + 1].addr >> 8 == page
            && OBJECTS[last + 1].end() - u32::from(start.addr) <= 125
        {
            last += 1;
        }
        let qty = (OBJECTS[last].end() - u32::from(start.addr)) as u16;
        let function = if self.rng.bool() { 0x03 } else { 0x04 };
        let mut pdu = vec![function];
        pdu.extend(start.addr.to_be_bytes());
        pdu.extend(qty.to_be_bytes());
        let to = self.addr(i);
        self.note(format!("axis {to}: read {qty} at {:#06X} ({function:02X})", start.addr));
        let r = self.request(to, &pdu)?.ok_or("no reply")?;
        if r[0] != function {
            return Err(format!("axis {to}: read of {qty} at {:#06X} refused: {r:02X?}", start.addr));
        }
        let words: Vec<u16> = r[2..].chunks_exact(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect();
        for d in &OBJECTS[first..=last] {
            let Some(&(obj, ..)) = SETTINGS.iter().find(|(o, ..)| *o == d.obj) else { continue };
            let k = usize::from(d.addr - start.addr);
            let value = if d.words() == 2 {
                (u32::from(words[k]) << 16) | u32::from(words[k + 1])
            } else {
                u32::from(words[k])
            };
            let expected = self.axes[i].rom.get(obj);
            if value != expected {
                return Err(format!("axis {to}: {obj:?} reads {value}, the master wrote {expected}"));
            }
        }
        Ok(())
    }

    /// Echo, or the counters against what the master sent; now and then clears them.
    fn diagnostics(&mut self, i: usize) -> Check {
        let to = self.addr(i);
        match self.rng.u32(0..10) {
            0 => {
                let data = [self.rng.u8(..), self.rng.u8(..)];
                self.note(format!("axis {to}: echo {data:02X?}"));
                let r = self.request(to, &[0x08, 0x00, 0x00, data[0], data[1]])?.ok_or("no reply")?;
                if r != [0x08, 0x00, 0x00, data[0], data[1]] {
                    return Err(format!("axis {to}: echo answered {r:02X?}"));
                }
                Ok(())
            }
            1 => {
                self.note(format!("axis {to}: clear the counters"));
                let r = self.request(to, &[0x08, 0x00, 0x0A, 0, 0])?.ok_or("no reply")?;
                if r != [0x08, 0x00, 0x0A, 0, 0] {
                    return Err(format!("axis {to}: clear counters answered {r:02X?}"));
                }
                self.axes[i].counts = Counts::default();
                Ok(())
            }
            _ => self.check_counters(i),
        }
    }

    /// Reads the counters 0x0B-0x0F of axis `i` and compares them with the master's.
    fn check_counters(&mut self, i: usize) -> Check {
        let to = self.addr(i);
        self.note(format!("axis {to}: counters"));
        for sub in [0x0Bu8, 0x0C, 0x0D, 0x0E, 0x0F] {
            let r = self.request(to, &[0x08, 0x00, sub, 0, 0])?.ok_or("no reply")?;
            let got = u16::from_be_bytes([r[3], r[4]]);
            let c = self.axes[i].counts;
            let want = match sub {
                0x0B => c.bus,
                0x0C => c.errors,
                0x0D => c.exceptions,
                0x0E => c.slave,
                _ => c.no_response,
            };
            if got != want {
                return Err(format!("axis {to}: counter {sub:02X} is {got}, the master counts {want} ({c:?})"));
            }
        }
        self.report.counter_checks += 1;
        Ok(())
    }

    fn device_id(&mut self, i: usize) -> Check {
        let to = self.addr(i);
        self.note(format!("axis {to}: device identification"));
        let r = self.request(to, &[0x2B, 0x0E, 0x01, 0x00])?.ok_or("no reply")?;
        if r[0] != 0x2B {
            return Err(format!("axis {to}: device identification refused: {r:02X?}"));
        }
        Ok(())
    }

    fn change_setting(&mut self, i: usize) -> Check {
        let (obj, lo, hi) = SETTINGS[self.rng.usize(0..SETTINGS.len())];
        let v = self.rng.u32(lo..=hi);
        self.note(format!("axis {}: {obj:?} = {v}", self.addr(i)));
        self.set(i, obj, v)
    }

    fn save_op(&mut self, i: usize) -> Check {
        self.note(format!("axis {}: save", self.addr(i)));
        self.save(i)
    }

    /// A supply dip on axis `i` (to 20-22 V and back, above the under-voltage threshold) or a
    /// load step within the motor's torque.
    fn disturb(&mut self, i: usize) -> Check {
        let addr = self.addr(i);
        self.report.disturbances += 1;
        if self.rng.bool() {
            let to_v = 20.0 + 2.0 * self.rng.f64();
            let ramp = 0.005 + 0.1 * self.rng.f64();
            let hold = self.rng.u64(10_000..500_000);
            self.note(format!("axis {addr}: supply dip to {to_v:.2} V for {} ms", hold / 1000));
            let back = self.now + (ramp * 1e6) as u64 + hold;
            let axis = &mut self.axes[i];
            axis.plant.inject(Change::SupplyRamp { to_v, seconds: ramp });
            axis.pending.push((back, Change::SupplyRamp { to_v: 24.0, seconds: ramp }));
        } else {
            let nm = LOAD_MAX_NM * (2.0 * self.rng.f64() - 1.0);
            self.note(format!("axis {addr}: load torque {nm:.4} N·m"));
            self.axes[i].plant.inject(Change::LoadTorque(nm));
        }
        Ok(())
    }

    /// A speed for axis `i`, pps, within what the motor follows.
    fn speed(&mut self, i: usize) -> i32 {
        let top = FULL_STEPS_PER_S_MAX * f64::from(self.axes[i].ustep);
        let lo = SLOWEST * top;
        (lo + (top - lo) * self.rng.f64()) as i32
    }

    /// A target for axis `i`: near, or far, within the span.
    fn target(&mut self, i: usize) -> i64 {
        let u = i64::from(self.axes[i].ustep);
        let here = self.axes[i].plant.drive().state().position();
        let reach = match self.rng.u32(0..4) {
            0 => 3,
            1 => 10 * u,
            2 => 400 * u,
            _ => 4000 * u,
        };
        let t = here + self.rng.i64(-reach..=reach);
        t.clamp(-FULL_STEPS_SPAN * u, FULL_STEPS_SPAN * u)
    }

    /// A relative move (0x6003..0x6006 in one write; the speed's sign sets the direction). While
    /// a move runs it is ignored, as §5.5.5 says.
    fn relative_move(&mut self, i: usize) -> Check {
        let speed = self.speed(i);
        let here = self.axes[i].plant.drive().state().position();
        let target = self.target(i);
        let steps = (target - here).unsigned_abs().max(1) as u32;
        let signed = if target < here { -speed } else { speed };
        let addr = self.addr(i);
        let running = match self.axes[i].motion {
            Motion::Move(Some(to)) => Some(to),
            _ => None,
        };
        if let Some(to) = running {
            // Ignored only if the move still runs when the frame is served, some ms from now:
            // sent only while the move has more than 50 ms to go at the fastest it may run.
            let v = self.axes[i].plant.outputs().map_or(0.0, |o| f64::from(o.setpoint.velocity.abs()));
            let fastest = v.max(f64::from(self.axes[i].max_speed.unsigned_abs())).max(f64::from(speed));
            if ((to - here).abs() as f64) < 0.05 * fastest + 10.0 {
                return self.absolute_move(i);
            }
        }
        self.note(format!(
            "axis {addr}: relative move {signed:+} pps, {steps} steps{}",
            if running.is_some() { " (while moving: ignored, its speed re-plans the move)" } else { "" }
        ));
        let [sh, sl] = words32(signed);
        let [dh, dl] = words32(steps as i32);
        self.write(i, Obj::MaxSpeed.def().addr, &[sh, sl, dh, dl])?;
        self.axes[i].max_speed = signed;
        if running.is_some() {
            self.report.retargets += 1;
        } else {
            let target = if signed < 0 { here - i64::from(steps) } else { here + i64::from(steps) };
            self.axes[i].motion = Motion::Move(Some(target));
        }
        Ok(())
    }

    /// An absolute move; while moving, a re-target.
    fn absolute_move(&mut self, i: usize) -> Check {
        let target = self.target(i);
        let retarget = matches!(self.axes[i].motion, Motion::Move(_));
        if !retarget || self.axes[i].max_speed == 0 {
            let speed = self.speed(i);
            self.write_speed(i, speed)?;
        }
        self.note(format!(
            "axis {}: absolute move to {target}{}",
            self.addr(i),
            if retarget { " (re-target)" } else { "" }
        ));
        self.write32(i, Obj::AbsoluteMove.def().addr, target as i32)?;
        self.axes[i].motion = Motion::Move(Some(target));
        if retarget {
            self.report.retargets += 1;
        }
        Ok(())
    }

    /// A new speed for the running position move.
    fn change_speed(&mut self, i: usize) -> Check {
        let speed = self.speed(i);
        self.note(format!("axis {}: speed {speed} pps while moving", self.addr(i)));
        if self.axes[i].plant.drive().state().read(Obj::ControllerStatus) as u8 & STATUS_BUSY == 0 {
            // The move ended meanwhile: the speed is only stored.
            return self.write_speed(i, speed);
        }
        self.write_speed(i, speed)?;
        self.report.retargets += 1;
        Ok(())
    }

    /// Velocity mode at a random speed and direction, for a while.
    fn velocity_run(&mut self, i: usize) -> Check {
        let speed = if self.rng.bool() { self.speed(i) } else { -self.speed(i) };
        // Long enough to cruise, short enough to stay within the span.
        let span = (FULL_STEPS_SPAN as f64 / 4.0) * f64::from(self.axes[i].ustep) / f64::from(speed.unsigned_abs());
        let until = self.now + (self.rng.f64() * span.min(30.0) * 1e6) as u64;
        self.note(format!("axis {}: velocity run at {speed} pps", self.addr(i)));
        self.write(i, Obj::Mode.def().addr, &[1])?;
        self.write_speed(i, speed)?;
        self.axes[i].motion = Motion::Velocity { speed, until };
        self.report.velocity_runs += 1;
        Ok(())
    }

    fn change_velocity(&mut self, i: usize) -> Check {
        let Motion::Velocity { until, .. } = self.axes[i].motion else { return Ok(()) };
        let speed = if self.rng.bool() { self.speed(i) } else { -self.speed(i) };
        self.note(format!("axis {}: velocity {speed} pps", self.addr(i)));
        self.write_speed(i, speed)?;
        self.axes[i].motion = Motion::Velocity { speed, until };
        self.report.retargets += 1;
        Ok(())
    }

    /// Ends a velocity run: speed 0 decelerates (or, half the time, position mode does).
    fn stop_velocity(&mut self, i: usize) -> Check {
        self.note(format!("axis {}: velocity run stops", self.addr(i)));
        if self.rng.bool() {
            self.write_speed(i, 0)?;
            self.axes[i].motion = Motion::Stopping;
        } else {
            self.write(i, Obj::Mode.def().addr, &[0])?;
            self.axes[i].motion = Motion::Move(None);
        }
        self.settle(i)
    }

    /// 0x6053 = 0: the setpoint stops at once. From speed the rotor overshoots and may slip to
    /// another step: the encoder check takes its offset anew once the motor rests.
    fn immediate_stop(&mut self, i: usize) -> Check {
        self.note(format!("axis {}: immediate stop", self.addr(i)));
        self.write(i, Obj::Stop.def().addr, &[0])?;
        self.report.stops += 1;
        let axis = &mut self.axes[i];
        axis.base = None;
        if matches!(axis.motion, Motion::Velocity { .. }) {
            self.write(i, Obj::Mode.def().addr, &[0])?;
        }
        self.axes[i].motion = Motion::Rest;
        Ok(())
    }

    /// Starts a synchronous move on a few resting axes with one broadcast.
    fn group_start(&mut self) -> Check {
        let resting: Vec<usize> = (0..self.axes.len()).filter(|&k| self.axes[k].motion == Motion::Rest).collect();
        if resting.is_empty() {
            return Ok(());
        }
        let members: Vec<usize> = resting.iter().copied().filter(|_| self.rng.u32(0..3) > 0).collect();
        let members = if members.is_empty() { vec![resting[0]] } else { members };
        // A group no other drive is in.
        let group = loop {
            let g = self.rng.u8(1..=127);
            if (0..self.axes.len()).all(|k| members.contains(&k) || self.axes[k].rom.get(Obj::GroupId) != u32::from(g))
            {
                break g;
            }
        };
        let mut targets = Vec::new();
        for &k in &members {
            self.set(k, Obj::GroupId, u32::from(group))?;
            let speed = self.speed(k);
            let target = self.target(k);
            let [sh, sl] = words32(speed);
            let [th, tl] = words32(target as i32);
            self.write(k, Obj::SyncSpeed.def().addr, &[sh, sl, th, tl])?;
            targets.push((k, target));
        }
        let list: Vec<u8> = members.iter().map(|&k| self.addr(k)).collect();
        self.note(format!("axes {list:?}: group {group} starts by broadcast"));
        self.write_to(0, Obj::GroupStart.def().addr, &[u16::from(group)])?
            .map_err(|c| format!("broadcast refused {c}"))?;
        for (k, target) in targets {
            self.axes[k].motion = Motion::Move(Some(target));
        }
        self.report.group_starts += 1;
        Ok(())
    }

    /// Stops the group of axis `i` by broadcast: its moving members decelerate to rest.
    fn group_stop(&mut self, i: usize) -> Check {
        let group = self.axes[i].rom.get(Obj::GroupId);
        if group == 0 {
            return Ok(());
        }
        self.note(format!("group {group} stops by broadcast"));
        self.write_to(0, Obj::GroupStop.def().addr, &[group as u16])?.map_err(|c| format!("broadcast refused {c}"))?;
        for a in &mut self.axes {
            if a.rom.get(Obj::GroupId) != group {
                continue;
            }
            match &mut a.motion {
                Motion::Move(_) => a.motion = Motion::Move(None),
                Motion::Stream(s) => s.stopped = true,
                _ => {}
            }
        }
        self.report.stops += 1;
        Ok(())
    }

    // --------------------------------------------------------------------------------------------
    // PVT streams.

    /// Starts a PVT stream on axis `i`: a smooth random path from rest to rest, sampled every
    /// 10-40 ms, pushed a point per 0x10 write (push on time) and refilled on the low mark.
    fn pvt_stream(&mut self, i: usize) -> Check {
        // The streams share the line: with this one they take at most half of it, the rest
        // being for the first fills and everything else (a master that planned otherwise would
        // run its FIFOs dry).
        let load: f64 = self
            .axes
            .iter()
            .filter_map(|a| match &a.motion {
                Motion::Stream(s) if !s.stopped => s.points.first().map(|p| PUSH_MS / f64::from(p.2)),
                _ => None,
            })
            .sum();
        let fastest = PUSH_MS / (STREAM_LOAD - load).max(1e-9);
        if fastest > 40.0 {
            let us = self.rng.u64(1_000..300_000);
            return self.wait(us);
        }
        let dt_ms = self.rng.u16(fastest.ceil().max(10.0) as u16..=40);
        let u = f64::from(self.axes[i].ustep);
        let p0 = self.axes[i].plant.drive().state().position() as f64;
        let n = self.rng.usize(20..600);
        let t_total = f64::from(dt_ms) * 1e-3 * n as f64;
        // Displacement D with the speed profile D/T (1 - cos): at rest at both ends, peak 2D/T;
        // plus ripples of k whole periods, at rest at both ends too.
        let v_top = 0.5 * FULL_STEPS_PER_S_MAX * u;
        let d = (2.0 * self.rng.f64() - 1.0) * 0.5 * v_top * t_total;
        let k = f64::from(self.rng.u32(1..4));
        let w = std::f64::consts::TAU * k / t_total;
        let ripple = (2.0 * self.rng.f64() - 1.0) * 0.5 * v_top / w;
        let w1 = std::f64::consts::TAU / t_total;
        let mut points = Vec::with_capacity(n);
        for s in 1..=n {
            let t = f64::from(dt_ms) * 1e-3 * s as f64;
            let p = p0
                + d * (t / t_total - (w1 * t).sin() / std::f64::consts::TAU)
                + ripple * (w * t).sin() * (w * t).sin();
            let v = d / t_total * (1.0 - (w1 * t).cos()) + ripple * w * (2.0 * w * t).sin();
            let v = if s == n { 0.0 } else { v };
            points.push((p.round() as i32, v.round() as i32, dt_ms));
        }
        let addr = self.addr(i);
        self.note(format!("axis {addr}: PVT stream of {n} points of {dt_ms} ms, {d:.0} steps"));
        self.write(i, Obj::Mode.def().addr, &[2])?;
        self.write(i, Obj::PvtMode.def().addr, &[2])?;
        self.write(i, Obj::PvtFifoDepth.def().addr, &FIFO)?;
        self.write(i, Obj::PvtAutoPush.def().addr, &[1])?;
        self.axes[i].motion =
            Motion::Stream(Stream { points, pushed: 0, started: false, filling: true, stopped: false, next_look: 0 });
        let mut queued = 0;
        loop {
            queued = self.refill(i, queued)?;
            if !matches!(&self.axes[i].motion, Motion::Stream(s) if s.filling) {
                break;
            }
            self.service_streams()?;
        }
        self.write(i, Obj::PvtControl.def().addr, &[1])?;
        if let Motion::Stream(s) = &mut self.axes[i].motion {
            s.started = true;
            s.next_look = self.now + 200_000;
        }
        Ok(())
    }

    /// Pushes up to [`PUSH_BURST`] points of axis `i`'s stream onto the `queued` the master
    /// last read (an upper bound: the drive only takes points away), stopping above the FIFO's
    /// high mark or at the stream's end, which ends the filling; the new bound.
    fn refill(&mut self, i: usize, mut queued: u16) -> Result<u16, String> {
        for _ in 0..PUSH_BURST {
            let Motion::Stream(s) = &mut self.axes[i].motion else { return Ok(queued) };
            s.filling = true;
            let Some(&(p, v, t)) = s.points.get(s.pushed) else {
                s.filling = false;
                return Ok(queued);
            };
            if queued > FIFO[2] {
                s.filling = false;
                return Ok(queued);
            }
            let [ph, pl] = words32(p);
            let [vh, vl] = words32(v);
            let [th, tl] = words32(i32::from(t));
            self.write(i, Obj::PvtPosition.def().addr, &[ph, pl, vh, vl, th, tl])?;
            self.report.pvt_points += 1;
            queued += 1;
            if let Motion::Stream(s) = &mut self.axes[i].motion {
                s.pushed += 1;
            }
        }
        Ok(queued)
    }

    /// Looks at the FIFO of every stream that is due (0x2110); below the low mark refills it a
    /// burst per look up to the high mark; ends a stream whose points are all pushed once it rests.
    fn service_streams(&mut self) -> Check {
        for i in 0..self.axes.len() {
            let Motion::Stream(s) = &self.axes[i].motion else { continue };
            if !s.started || self.now < s.next_look {
                continue;
            }
            let all = s.stopped || s.pushed == s.points.len();
            let filling = s.filling;
            let queued = self.read(i, Obj::PvtCount.def().addr, 1)?[0];
            if !all && (queued < FIFO[1] || filling) {
                self.refill(i, queued)?;
            }
            if let Motion::Stream(s) = &mut self.axes[i].motion {
                s.next_look = self.now + if s.filling { 0 } else { 200_000 };
            }
            let stopped = matches!(&self.axes[i].motion, Motion::Stream(s) if s.stopped);
            if all
                && (queued == 0 || stopped)
                && self.axes[i].plant.drive().state().read(Obj::ControllerStatus) as u8 & STATUS_BUSY == 0
            {
                self.settle(i)?;
            }
        }
        Ok(())
    }
}

/// A 32-bit value as the native map's two registers, high word first.
fn words32(v: i32) -> [u16; 2] {
    [((v as u32) >> 16) as u16, v as u16]
}

/// Whether `pdu` is a diagnostics request that only reads (echo or a counter).
fn is_counter_read(pdu: &[u8]) -> bool {
    pdu.first() == Some(&0x08)
        && pdu.get(1) == Some(&0)
        && pdu.get(2).is_some_and(|&s| s == 0 || (0x0B..=0x12).contains(&s))
}

/// Checks that `reply` is a well-formed answer to `req` (both whole frames).
fn check_reply(req: &[u8], reply: &[u8]) -> Check {
    let bad = |why: &str| Err(format!("{why}: {reply:02X?} answering {req:02X?}"));
    if reply.len() < 5 || !drive_core::crc::frame_ok(reply) {
        return bad("malformed reply");
    }
    if reply[0] != req[0] {
        return bad("reply from another address");
    }
    let f = req[1];
    if reply[1] == f | 0x80 {
        if reply.len() != 5 || !(1..=4).contains(&reply[2]) {
            return bad("malformed exception");
        }
        return Ok(());
    }
    if reply[1] != f {
        return bad("another function code");
    }
    let be16 = |b: &[u8], at: usize| usize::from(u16::from_be_bytes([b[at], b[at + 1]]));
    let ok = match f {
        0x03 | 0x04 => {
            let qty = be16(req, 4);
            usize::from(reply[2]) == 2 * qty && reply.len() == 5 + 2 * qty
        }
        0x06 => reply == req,
        0x10 => reply.len() == 8 && reply[..6] == req[..6],
        0x08 => reply.len() == 8 && reply[2..4] == req[2..4] && (be16(req, 2) != 0 || reply == req),
        0x2B => reply[2] == 0x0E,
        _ => false,
    };
    if ok { Ok(()) } else { bad("reply does not answer the request") }
}

const _: () = {
    // The settings the master changes are saved ones it may write.
    let mut k = 0;
    while k < SETTINGS.len() {
        let d = &OBJECTS[SETTINGS[k].0 as usize];
        assert!(matches!(d.access(), Access::Rw) && matches!(d.storage(), Storage::Rom));
        k += 1;
    }
    assert!(TICK_MICROS <= CHECK_US);
};
