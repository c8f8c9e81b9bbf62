//! The scope and the black box over the native map's registers: a capture of a move is the
//! tick's own setpoints, triggers fire where they should, an alarm freezes the black box.

mod common;

use common::MapRig;
use drive_core::maps::Maps;

const SIGNAL1: u16 = 0x2220;
const DIVIDER: u16 = 0x2228;
const TRIGGER: u16 = 0x2229;
const TRIGGER_SIGNAL: u16 = 0x222A;
const LEVEL: u16 = 0x222B;
const PRE: u16 = 0x222D;
const CONTROL: u16 = 0x222F;
const STATE: u16 = 0x2230;
const READ: u16 = 0x2232;
const WINDOW: u16 = 0x4000;

fn rig() -> MapRig {
    MapRig::new(Maps::by_id(0))
}

fn write32(r: &mut MapRig, addr: u16, v: i32) {
    let [a, b] = addr.to_be_bytes();
    let [c, d, e, f] = v.to_be_bytes();
    r.request(&[1, 0x10, a, b, 0, 2, 4, c, d, e, f]).unwrap();
}

fn signals(r: &mut MapRig, codes: &[u16]) {
    for k in 0..8 {
        r.write(SIGNAL1 + k, codes.get(usize::from(k)).copied().unwrap_or(0)).unwrap();
    }
}

/// The capture held: (state, sequence, last read, rows, row words, trigger row) and its words,
/// read as a master reads it (blocks of 125), checked whole.
fn capture(r: &mut MapRig) -> (Vec<u16>, Vec<u16>) {
    let head = r.read(STATE, 6).unwrap();
    let n = usize::from(head[3]) * usize::from(head[4]);
    let mut words = Vec::new();
    while words.len() < n {
        let k = words.len();
        let q = (n - k).min(125) as u16;
        words.extend(r.read(WINDOW + k as u16, q).unwrap());
    }
    assert_eq!(r.read(STATE, 2).unwrap(), head[..2], "the capture changed while read");
    (head, words)
}

fn rows32(words: &[u16], width: usize, at: usize) -> Vec<i32> {
    words.chunks(width).map(|row| (i32::from(row[at]) << 16) | i32::from(row[at + 1])).collect()
}

#[test]
fn a_capture_of_a_move_is_the_ticks_setpoints_from_its_start() {
    let mut r = rig();
    r.write(0x600C, 16).unwrap(); // 16 microsteps
    signals(&mut r, &[1, 4]); // commanded position, commanded velocity: 4 words a row
    r.write(DIVIDER, 16).unwrap();
    r.write(TRIGGER, 1).unwrap(); // a move's start
    r.write(PRE, 10).unwrap();
    r.write(CONTROL, 1).unwrap();
    assert_eq!(r.read(STATE, 2).unwrap(), [1, 0]);
    write32(&mut r, 0x6003, 20_000);
    // Time to fill the pre-trigger share (a trigger before that keeps fewer rows before it).
    r.run(200_000);
    let start = r.drive.state().position();
    write32(&mut r, 0x6005, 3_000);
    r.run(2_000_000);
    let (head, words) = capture(&mut r);
    let [state, sequence, _, rows, width, trigger] = head[..] else { unreachable!() };
    assert_eq!((state, sequence, width), (3, 1, 4));
    assert_eq!((rows, trigger), (2048, 204), "10 % of 2048 rows before the move's start");
    assert_eq!(r.read(0x2236, 2).unwrap(), [0, 800], "16 ticks of 50 µs between rows");
    let position = rows32(&words, 4, 0);
    let velocity = rows32(&words, 4, 2);
    // Before the trigger the motor stood; at it the first step; at the end the target.
    assert!(position[..204].iter().all(|&p| i64::from(p) == start));
    assert!(velocity[..204].iter().all(|&v| v == 0));
    assert!(velocity[204] > 0);
    assert_eq!(i64::from(*position.last().unwrap()), start + 3_000);
    // Rows 16 ticks (800 µs) apart: at most 20 000 microsteps/s × 800 µs between two.
    assert!(position.windows(2).all(|w| (0..=16).contains(&(w[1] - w[0]))));
    // Read: a one-shot scope goes idle.
    r.write(READ, sequence).unwrap();
    assert_eq!(r.read(STATE, 1).unwrap(), [0]);
}

#[test]
fn a_level_trigger_fires_at_the_first_row_past_the_level() {
    let mut r = rig();
    signals(&mut r, &[1]);
    r.write(DIVIDER, 10).unwrap();
    r.write(TRIGGER, 2).unwrap(); // rising
    r.write(TRIGGER_SIGNAL, 1).unwrap();
    write32(&mut r, LEVEL, 1_000);
    r.write(PRE, 50).unwrap();
    r.write(CONTROL, 1).unwrap();
    write32(&mut r, 0x6003, 4_000);
    write32(&mut r, 0x6005, 6_000);
    r.run(2_000_000);
    let (head, words) = capture(&mut r);
    let t = usize::from(head[5]);
    let position = rows32(&words, 2, 0);
    assert!(position[t] >= 1_000 && position[t - 1] < 1_000, "{} {}", position[t - 1], position[t]);
}

#[test]
fn arming_without_a_signal_is_refused_and_changes_nothing() {
    let mut r = rig();
    signals(&mut r, &[]);
    let before = r.read(STATE, 6).unwrap();
    assert_eq!(r.write(CONTROL, 1), Err(4));
    assert_eq!(r.read(STATE, 6).unwrap(), before);
    // A level trigger with no signal to watch.
    signals(&mut r, &[3]);
    r.write(TRIGGER, 2).unwrap();
    assert_eq!(r.write(CONTROL, 1), Err(4));
    // Out of range.
    assert_eq!(r.write(SIGNAL1, 16), Err(3));
    assert_eq!(r.write(DIVIDER, 0), Err(3));
    assert_eq!(r.write(DIVIDER, 1), Err(3), "every second tick at the most");
    // The windows are read only, and end where they end.
    assert_eq!(r.write(WINDOW, 1), Err(2));
    assert_eq!(r.read(0x5FFF, 2), Err(2));
    assert_eq!(r.read(0x5FFF, 1).map(|w| w.len()), Ok(1));
}

#[test]
fn an_alarm_freezes_the_black_box_with_the_second_before_it() {
    let mut r = rig();
    write32(&mut r, 0x6003, 2_000);
    write32(&mut r, 0x6005, 1_000_000);
    r.inputs.supply_mv = Some(24_000);
    r.run(1_500_000);
    assert_eq!(r.read(0x2238, 1).unwrap(), [1], "recording");
    // Over-voltage: alarm 14.
    r.inputs.supply_mv = Some(70_000);
    r.run(400_000);
    let head = r.read(0x2238, 7).unwrap();
    let [state, sequence, _read, rows, trigger, fault_hi, fault_lo] = head[..] else { unreachable!() };
    assert_eq!((state, sequence, rows, trigger), (3, 1, 1024, 819));
    let history = r.read(0x213C, 2).unwrap();
    assert_eq!([fault_hi, fault_lo], history[..], "the capture names the history's newest entry");
    assert_eq!(fault_hi >> 8, 14);
    let mut words = Vec::new();
    while words.len() < 1024 * 8 {
        let k = words.len() as u16;
        words.extend(r.read(0xA000 + k, 125.min(8192 - k)).unwrap());
    }
    // Supply (word 4 of a row): 24 V for the second before, 70 V from the alarm's row on.
    let supply: Vec<u16> = words.chunks(8).map(|row| row[4]).collect();
    assert!(supply[..819].iter().all(|&v| v == 24_000));
    assert_eq!(supply[819], 65_535, "70 V, saturated in 16 bits");
    // Velocity (words 0-1): the drive was moving at 2 000 microsteps/s until the alarm.
    assert_eq!(rows32(&words, 8, 0)[..819].iter().filter(|&&v| v == 2_000).count(), 819);
    // Read: it records again.
    r.write(0x223A, sequence).unwrap();
    assert_eq!(r.read(0x2238, 1).unwrap(), [1]);
}

#[test]
fn every_map_reaches_the_scope_in_its_own_codes() {
    use drive_core::maps::layout::SCOPE_RANGES;
    for id in 1..=4 {
        let map = Maps::by_id(id);
        let Maps::Layout(layout) = &map else { unreachable!() };
        let layout = layout.layout();
        if layout.scope {
            // Nothing of the map's own lies where the native scope is.
            let own = layout.entries.iter().map(|e| (e.addr, e.addr + e.words() as u16 - 1));
            let own = own.chain(layout.reserved.iter().copied());
            let own = own.chain(layout.program.map(|p| (p.first, p.first + p.words - 1)));
            for (lo, hi) in own {
                assert!(SCOPE_RANGES.iter().all(|&(a, b)| hi < a || lo > b), "map {id}: 0x{lo:04X}-0x{hi:04X}");
            }
        } else {
            assert!(layout.sub_index.is_some(), "map {id} reaches the scope through its window");
            continue;
        }
        let mut r = MapRig::new(map);
        r.write(SIGNAL1, 9).unwrap();
        r.write(SIGNAL1 + 1, 0).unwrap();
        r.write(SIGNAL1 + 2, 0).unwrap();
        r.write(SIGNAL1 + 3, 0).unwrap();
        r.write(DIVIDER, 2).unwrap();
        r.write(CONTROL, 1).unwrap();
        r.run(1_000_000);
        let (head, words) = capture(&mut r);
        assert_eq!((head[0], head[3], head[4]), (3, 8192, 1), "map {id}");
        assert_eq!(words.len(), 8192);
        // Out of range: the map's own code for it, as for its own registers.
        let code = layout.exceptions.out_of_range.code();
        assert_eq!(r.write(SIGNAL1, 99), Err(code), "map {id}");
    }
}
