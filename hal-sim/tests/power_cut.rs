//! An update through embassy-boot on the simulated G474 slots: a power cut at every flash
//! operation of it (the transfer into DFU, the mark, the swap, the new image's first boot and
//! its confirmation, the rollback of an unconfirmed one) with every kind of tear leaves the old
//! or the new image to boot, never neither, and the drive settles on the right one.
//!
//! `cargo test -p hal-sim --test power_cut -- --nocapture` prints the counts.

use drive_core::update::{Board, Header, MAX_PROGRAM, SIGNATURE_LEN, TRAILER, TRAILER_LEN};
use embassy_boot::State;
use hal_sim::flash::{SimFlash, Tear};
use hal_sim::slots::{SlotError, Slots, UPDATE_START};

/// Bytes a bus transfer carries at a time (a Modbus write of 120 registers).
const CHUNK: usize = 240;
/// Resets after a cut: enough for a resumed swap, the first boot, a rollback and one more.
const RESETS: usize = 5;

/// A program and its trailer.
struct Image {
    program: Vec<u8>,
    trailer: Vec<u8>,
}

impl Image {
    /// Image `version`, `len` program bytes of its own pseudo-random content.
    fn new(version: u32, len: u32) -> Self {
        let mut rng = fastrand::Rng::with_seed(u64::from(version));
        let mut program = vec![0; len as usize];
        rng.fill(&mut program);
        let header = Header { board: Board::Simulator, version, length: len, store: 1 };
        let mut trailer = header.to_bytes().to_vec();
        trailer.extend((0..SIGNATURE_LEN).map(|_| rng.u8(..)));
        assert_eq!(trailer.len(), TRAILER_LEN);
        Self { program, trailer }
    }

    /// Whether ACTIVE holds exactly this image.
    fn in_active(&self, slots: &Slots) -> bool {
        let active = slots.active();
        active[..self.program.len()] == self.program[..]
            && active[TRAILER as usize..][..TRAILER_LEN] == self.trailer[..]
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Runs {
    Old,
    New,
}

/// An update from `old` to `new`, which confirms itself or not.
struct Update {
    old: Image,
    new: Image,
    confirms: bool,
}

impl Update {
    /// A drive flashed with the old image.
    fn drive(&self) -> Slots {
        let mut slots = Slots::new();
        slots.install(&self.old.program, &self.old.trailer).expect("flashing the old image");
        slots
    }

    /// Which image ACTIVE holds: it must be one of them, whole.
    fn runs(&self, slots: &Slots) -> Runs {
        match (self.old.in_active(slots), self.new.in_active(slots)) {
            (true, false) => Runs::Old,
            (false, true) => Runs::New,
            _ => panic!("ACTIVE holds neither the old nor the new image"),
        }
    }

    /// A reset and what the started application does: the new image on trial confirms itself
    /// if it is the one that works; an image not on trial does nothing.
    fn reset(&self, slots: &mut Slots) -> Result<Runs, SlotError> {
        let boot = slots.boot()?;
        let runs = self.runs(slots);
        if runs == Runs::New && boot.state == UPDATE_START && self.confirms {
            slots.mark_booted()?;
        }
        Ok(runs)
    }

    /// The whole update as the drive does it, with nothing cut: the operation count at the end
    /// of each step.
    fn run(&self, slots: &mut Slots, steps: &mut Vec<(&'static str, u64)>) -> Result<(), SlotError> {
        let mut step = |slots: &Slots, name| steps.push((name, slots.flash().ops()));
        let new = &self.new;
        let program = new.program.chunks(CHUNK).scan(0, |at, c| Some((std::mem::replace(at, *at + c.len()), c)));
        for (at, chunk) in program.chain([(TRAILER as usize, &new.trailer[..])]) {
            slots.write_dfu(at as u32, chunk)?;
        }
        step(slots, "transfer");
        slots.mark_updated()?;
        step(slots, "mark updated");
        assert_eq!(slots.boot()?.state, UPDATE_START);
        assert_eq!(self.runs(slots), Runs::New, "the swap");
        step(slots, "swap");
        // An image on trial takes no update: it must confirm first.
        assert_eq!(slots.write_dfu(0, &new.program[..CHUNK]), Err(SlotError::BadState));
        if self.confirms {
            slots.mark_booted()?;
            step(slots, "mark booted");
        }
        let want = if self.confirms { Runs::New } else { Runs::Old };
        assert_eq!(self.reset(slots)?, want, "the reset after the first boot");
        step(slots, if self.confirms { "reset" } else { "rollback" });
        assert_eq!(self.reset(slots)?, want, "the next reset");
        step(slots, "reset");
        assert_eq!(slots.state()?, if self.confirms { State::Boot } else { State::Revert });
        Ok(())
    }

    /// Cuts the power at every operation of the update with every tear, powers up and resets
    /// until the drive settles: the cases tested for each tear.
    fn every_cut(&self) -> [u64; Tear::ALL.len()] {
        let mut steps = Vec::new();
        let mut slots = self.drive();
        let from = slots.flash().ops();
        self.run(&mut slots, &mut steps).expect("the update");
        let steps: Vec<_> = steps.into_iter().map(|(name, at)| (name, at - from)).collect();
        let ops = slots.flash().ops() - from;
        let test = std::thread::current().name().unwrap_or_default().to_owned();
        eprintln!("{test}: {ops} operations, at the end of each step {steps:?}");
        let at = |step| steps.iter().find(|(name, _)| *name == step).map_or(0, |s| s.1);
        let (marked, swapped) = (at("mark updated"), at("swap"));
        let mut cases = [0; Tear::ALL.len()];
        for (tear, count) in Tear::ALL.into_iter().zip(&mut cases) {
            for n in 0..ops {
                let mut slots = self.drive();
                slots.flash_mut().cut_after(n, tear);
                let cut = self.run(&mut slots, &mut Vec::new());
                assert_eq!(cut, Err(SlotError::PowerCut), "op {n} {tear:?}");
                let bytes = slots.into_flash().bytes().to_vec();
                let mut slots = Slots::from_flash(SimFlash::from_bytes(bytes));
                let runs: Vec<Runs> = (0..RESETS)
                    .map(|k| self.reset(&mut slots).unwrap_or_else(|e| panic!("op {n} {tear:?} reset {k}: {e:?}")))
                    .collect();
                let want = if self.confirms && kept(n, tear, marked, swapped) { Runs::New } else { Runs::Old };
                assert_eq!(runs[RESETS - 2..], [want, want], "op {n} {tear:?}: {runs:?}");
                *count += 1;
            }
        }
        eprintln!("{test}: cases (Nothing, Half, Garbled, Complete) {cases:?}, {} in all", cases.iter().sum::<u64>());
        cases
    }
}

/// Whether an update that confirms itself at its first boot is kept after a cut at operation `n`
/// torn as `tear`, `marked` and `swapped` the operation counts at the end of the mark and the
/// swap. STATE's magic and the swap's progress are single double words: the magic counts only
/// whole, a progress entry or the confirmation's first word (which voids the progress) as soon
/// as any bit of it is programmed.
fn kept(n: u64, tear: Tear, marked: u64, swapped: u64) -> bool {
    let landed = matches!(tear, Tear::Garbled | Tear::Complete);
    match n + 1 {
        k if k < marked => false,
        k if k == marked => tear == Tear::Complete,
        // The swap resumes at the reset and the new image confirms at its first boot.
        k if k < swapped => true,
        // The swap done but its boot cut before the new image started: it never confirmed and
        // the next reset rolls it back.
        k if k == swapped => !landed,
        // Its confirmation: the first word decides.
        k if k == swapped + 1 => landed,
        _ => true,
    }
}

const SMALL: u32 = 20 * 1024;

#[test]
fn a_confirmed_update_boots_old_or_new_at_every_cut() {
    let update = Update { old: Image::new(1, SMALL), new: Image::new(2, SMALL + 8), confirms: true };
    update.every_cut();
}

#[test]
fn an_unconfirmed_update_rolls_back_at_every_cut() {
    let update = Update { old: Image::new(1, SMALL), new: Image::new(2, SMALL + 8), confirms: false };
    update.every_cut();
}

#[test]
fn a_full_slot_update_boots_old_or_new_at_every_cut() {
    let update = Update { old: Image::new(1, MAX_PROGRAM), new: Image::new(2, MAX_PROGRAM), confirms: true };
    update.every_cut();
}
