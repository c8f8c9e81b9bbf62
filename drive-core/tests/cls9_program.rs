//! Seed 002's multi-segment programs (§7) at the level of frames: a program written to
//! 1024-1536 runs its moves, speeds, waits and loops on the axis; the check and a refused start
//! name the segment in error; inputs select the segment; pause, resume, end and stop; the
//! registers refuse writes while a program runs; PVT points leave the program whole; the native
//! map has no program.

mod common;

use drive_core::maps::Maps;
use drive_core::od::Obj;

type Rig = common::MapRig;

/// 1: absolute run.
fn abs(p: i32) -> Vec<u16> {
    vec![1, (p >> 16) as u16, p as u16]
}
/// 2: relative run.
fn rel(d: i32) -> Vec<u16> {
    vec![2, (d >> 16) as u16, d as u16]
}
/// 54: run speed, 0.01 rev/s.
fn speed(v: u16) -> Vec<u16> {
    vec![54, v]
}
/// 61 and 62: both ramps, rev/s².
fn ramps(a: u16) -> Vec<u16> {
    vec![61, a, 62, a]
}
/// 65: wait `ms`, then go on at instruction `to`.
fn wait(to: u16, ms: u16) -> Vec<u16> {
    vec![65, to, ms]
}
/// 66: loop back to `to` until the body ran `count` times.
fn again(count: u16, to: u16) -> Vec<u16> {
    vec![66, count, to]
}
const END: [u16; 1] = [100];

/// A DS-CLS9 drive at 3200 pulses a revolution with `program` in its registers.
fn rig(program: &[Vec<u16>]) -> Rig {
    let mut r = Rig::new(Maps::cls9());
    r.request(&[1, 0x10, 0, 242, 0, 2, 4, 0, 0, 0x0C, 0x80]).expect("resolution");
    let words: Vec<u16> = program.concat();
    r.store(&words).expect("program");
    r
}

impl Rig {
    /// Writes `words` from 1024, 100 a request.
    fn store(&mut self, words: &[u16]) -> Result<(), u8> {
        for (k, chunk) in words.chunks(100).enumerate() {
            let addr = 1024 + 100 * k as u16;
            let [a, b] = addr.to_be_bytes();
            let mut body = vec![1, 0x10, a, b, 0, chunk.len() as u8, 2 * chunk.len() as u8];
            body.extend(chunk.iter().flat_map(|w| w.to_be_bytes()));
            self.request(&body)?;
        }
        Ok(())
    }

    fn reg(&mut self, addr: u16) -> u16 {
        self.read(addr, 1).expect("read")[0]
    }

    fn position(&self) -> i64 {
        i64::from(self.drive.state().read_i32(Obj::Position))
    }

    /// Runs until no segment runs (at most `s` seconds); the time it took, ms.
    fn finish(&mut self, s: u64) -> u64 {
        for k in 0..s * 100 {
            self.run(10_000);
            if self.drive.state().read(Obj::ProgramRunning) == 0 {
                return 10 * (k + 1);
            }
        }
        panic!("the program still runs after {s} s");
    }
}

/// Segment 1: speed 5 rev/s, ramps 50 rev/s², to 6400, a 100 ms wait, then three times 1000
/// back; segment 2: home to 0.
fn two_segments() -> Vec<Vec<u16>> {
    vec![
        speed(500),   // 0
        ramps(50),    // 1, 2
        abs(6400),    // 3
        wait(5, 100), // 4
        rel(-1000),   // 5
        again(3, 5),  // 6
        END.to_vec(), // 7
        abs(0),       // 8
        END.to_vec(), // 9
    ]
}

#[test]
fn a_segment_runs_its_moves_waits_and_loops_and_the_next_one_runs_on_its_own_start() {
    let mut r = rig(&two_segments());
    r.set_segments(2);
    // The registers read back as written.
    assert_eq!(r.read(1024, 4).expect("program"), vec![54, 500, 61, 50]);
    assert_eq!(r.write(323, 14), Ok(()));
    assert_eq!(r.reg(176), 0, "no segment in error");
    assert_eq!(r.write(323, 16), Ok(()));
    r.run(20_000);
    assert_eq!(r.reg(178), 1, "segment 1 runs");
    assert_eq!(r.reg(109), 3, "running");
    // While it runs, the other motion commands are refused, and so are program writes.
    assert_eq!(r.write(323, 1), Err(0x04));
    assert_eq!(r.write(1024, 54), Err(0x04));
    let mut lowest = i64::MAX;
    let mut reached = false;
    for _ in 0..400 {
        r.run(5_000);
        reached |= r.position() == 6400;
        if reached {
            lowest = lowest.min(r.position());
        }
        if r.reg(178) == 0 {
            break;
        }
    }
    assert!(reached, "to 6400 first");
    assert_eq!(r.position(), 6400 - 3000, "the body ran three times");
    assert_eq!(lowest, 3400);
    // Segment 2, by 0328.
    assert_eq!(r.write(328, 1), Ok(()));
    assert_eq!(r.write(323, 16), Ok(()));
    r.finish(5);
    assert_eq!(r.position(), 0);
}

impl Rig {
    fn set_segments(&mut self, n: u16) {
        assert_eq!(self.write(327, n), Ok(()));
    }
}

#[test]
fn the_wait_holds_the_axis_for_its_time() {
    let mut r = rig(&[speed(500), ramps(50), abs(1600), wait(5, 300), abs(0), END.to_vec()]);
    r.write(323, 16).expect("start");
    let mut still_at = None;
    for k in 0..300u64 {
        r.run(5_000);
        if r.position() == 1600 && still_at.is_none() {
            still_at = Some(k);
        }
        if still_at.is_some() && r.position() != 1600 {
            let waited = 5 * (k - still_at.unwrap_or(k));
            assert!((290..=330).contains(&waited), "waited {waited} ms");
            break;
        }
    }
    r.finish(5);
    assert_eq!(r.position(), 0);
}

#[test]
fn a_loop_of_zero_runs_until_ended_and_a_pause_resumes_the_move() {
    let mut r = rig(&[speed(500), ramps(50), abs(3200), abs(0), again(0, 3), END.to_vec()]);
    r.write(323, 16).expect("start");
    r.run(2_000_000);
    assert_eq!(r.reg(178), 1, "still looping");
    // Pause: the axis stops short of its target; resume finishes the move.
    r.run(100_000);
    assert_eq!(r.write(323, 17), Ok(()));
    r.run(500_000);
    let paused_at = r.position();
    assert_eq!(r.reg(109), 2, "standing");
    r.run(200_000);
    assert_eq!(r.position(), paused_at, "paused");
    assert_eq!(r.reg(178), 1, "paused, not ended");
    assert_eq!(r.write(323, 16), Ok(()));
    r.run(100_000);
    assert_eq!(r.reg(109), 3, "moving again");
    // End: the segment is over, the axis stops at its deceleration.
    assert_eq!(r.write(323, 18), Ok(()));
    r.run(1_000_000);
    assert_eq!(r.reg(178), 0);
    let there = r.position();
    r.run(500_000);
    assert_eq!(r.position(), there, "nothing moves after the end");
}

#[test]
fn a_stop_ends_the_program() {
    let mut r = rig(&[speed(500), ramps(50), abs(32_000), abs(0), END.to_vec()]);
    r.write(323, 16).expect("start");
    r.run(300_000);
    assert_eq!(r.write(323, 6), Ok(()));
    r.run(1_000_000);
    assert_eq!(r.reg(178), 0);
    let there = r.position();
    assert!(there > 0 && there < 32_000, "{there}");
    r.run(1_000_000);
    assert_eq!(r.position(), there, "the next move never starts");
}

#[test]
fn errors_name_their_segment_and_a_start_of_a_program_in_error_moves_nothing() {
    // Segment 2 has an unknown code.
    let mut bad = two_segments();
    bad[8] = vec![3, 0, 0];
    let mut r = rig(&bad);
    r.set_segments(2);
    assert_eq!(r.write(323, 14), Ok(()));
    assert_eq!(r.reg(176), 2);
    assert_eq!(r.write(323, 16), Err(0x04));
    assert_eq!(r.reg(176), 2);
    r.run(500_000);
    assert_eq!(r.position(), 0, "nothing moved");
    assert_eq!(r.reg(178), 0);
    // One segment only: segment 1 is sound.
    r.set_segments(1);
    assert_eq!(r.write(323, 14), Ok(()));
    assert_eq!(r.reg(176), 0);
    // Segment 2 selected beyond 0327: refused.
    assert_eq!(r.write(328, 1), Ok(()));
    assert_eq!(r.write(323, 16), Err(0x04));

    for (program, why) in [
        (vec![speed(5001), END.to_vec()], "speed out of range"),
        (vec![speed(1), END.to_vec()], "a speed the drive cannot run (32 pulses/s)"),
        (vec![abs(5), wait(9, 10), END.to_vec()], "a jump outside the segment"),
        (vec![abs(5), vec![65, 0x0100, 10], END.to_vec()], "65's high byte not 0"),
        (vec![abs(5)], "no end code"),
        (vec![vec![61, 4], END.to_vec()], "acceleration below 5"),
    ] {
        let mut r = rig(&program);
        assert_eq!(r.write(323, 14), Ok(()), "{why}");
        assert_eq!(r.reg(176), 1, "{why}");
        assert_eq!(r.write(323, 16), Err(0x04), "{why}");
        assert_eq!(r.reg(178), 0, "{why}");
    }
    // Nine counted loops in one segment: beyond the counters kept.
    let mut nine = vec![abs(5)];
    nine.extend((0..9).map(|_| again(2, 0)));
    nine.push(END.to_vec());
    let mut r = rig(&nine);
    assert_eq!(r.write(323, 14), Ok(()));
    assert_eq!(r.reg(176), 1);
}

#[test]
fn inputs_select_the_segment_as_the_manuals_example_and_start_it() {
    let mut r =
        rig(&[abs(800), END.to_vec(), abs(-800), END.to_vec(), abs(1600), END.to_vec(), abs(2400), END.to_vec()]);
    r.set_segments(4);
    assert_eq!(r.reg(174), 0, "no input selects");
    // §7's example: IN1 select bit 0 (25), IN3 select bit 1 (26); IN2 starts (16).
    for (reg, f) in [(400, 25), (402, 26), (401, 16)] {
        assert_eq!(r.write(reg, f), Ok(()));
    }
    // Its table: IN3 IN1 = 00 segment 1, 01 segment 2, 10 segment 3, 11 segment 4.
    for (in3, in1, segment) in [(0, 0, 1), (0, 1, 2), (1, 0, 3), (1, 1, 4)] {
        assert_eq!(r.write(410, in1), Ok(()));
        assert_eq!(r.write(412, in3), Ok(()));
        assert_eq!(r.reg(174), segment, "IN3 {in3} IN1 {in1}");
    }
    // 0328 does not count while inputs select.
    assert_eq!(r.write(328, 0), Ok(()));
    assert_eq!(r.write(410, 0), Ok(()), "IN3 on, IN1 off: segment 3");
    assert_eq!(r.write(411, 1), Ok(()), "IN2: start");
    r.finish(5);
    assert_eq!(r.position(), 1600);
    assert_eq!(r.write(411, 0), Ok(()));
    assert_eq!(r.write(412, 0), Ok(()));
    assert_eq!(r.write(410, 1), Ok(()), "IN1 on: segment 2");
    assert_eq!(r.write(411, 1), Ok(()));
    r.finish(5);
    assert_eq!(r.position(), -800);
}

#[test]
fn a_start_is_refused_with_the_power_stage_off_and_requests_past_the_end_are_refused() {
    let mut r = rig(&[abs(800), END.to_vec()]);
    // The window is 1024..=1536.
    assert_eq!(r.read(1535, 2), Ok(vec![0, 0]));
    assert_eq!(r.read(1536, 2), Err(0x02));
    assert_eq!(r.write(1536, 7), Ok(()));
    assert_eq!(r.read(1536, 1), Ok(vec![7]));
    assert_eq!(r.write(1537, 7), Err(0x02));
    assert_eq!(r.request(&[1, 0x10, 0x06, 0x00, 0, 2, 4, 0, 1, 0, 2]).map(|_| ()), Err(0x02));
    assert_eq!(r.read(1536, 1), Ok(vec![7]), "a refused write changes nothing");
    r.drive.state_mut().apply(Obj::Enable, 0);
    r.run(10_000);
    assert_eq!(r.write(323, 16), Err(0x04));
    r.run(200_000);
    assert_eq!(r.position(), 0);
    assert_eq!(r.reg(178), 0);
}

/// The program has a memory of its own beside the PVT point table: points that fill the table
/// over where a program kept in its bytes would lie leave the program whole, and it runs.
#[test]
fn pvt_points_leave_the_program_whole() {
    let program = vec![speed(500), abs(3200), END.to_vec()];
    let mut r = rig(&program);
    let words: Vec<u16> = program.concat();
    let set = |r: &mut Rig, obj: Obj, v: u32| {
        let st = r.drive.state_mut();
        st.check(obj, v).unwrap_or_else(|e| panic!("{obj:?} = {v}: {e:?}"));
        st.apply(obj, v);
    };
    set(&mut r, Obj::Mode, 2);
    // 200 points of 9 bytes: past the program's 1 KB.
    for k in 0..200u32 {
        set(&mut r, Obj::PvtPosition, 10 * k);
        set(&mut r, Obj::PvtVelocity, 0);
        set(&mut r, Obj::PvtTime, 10);
        set(&mut r, Obj::PvtControl, 2);
    }
    assert_eq!(r.drive.state().read(Obj::PvtCount), 200);
    assert_eq!(r.read(1024, words.len() as u16), Ok(words));
    set(&mut r, Obj::Mode, 0);
    assert_eq!(r.write(323, 14), Ok(()));
    assert_eq!(r.reg(176), 0, "no segment in error");
    assert_eq!(r.write(323, 16), Ok(()));
    r.finish(5);
    assert_eq!(r.position(), 3200);
}

#[test]
fn the_native_map_has_no_program() {
    let mut r = Rig::new(Maps::by_id(0));
    for c in 14..=18u16 {
        assert_eq!(r.write(0x21A0, c), Err(0x04), "command {c}");
    }
    assert_eq!(r.read(0x21CF, 1), Ok(vec![0]));
}

#[test]
fn only_the_cls9_and_servo_maps_have_a_program_window() {
    use drive_core::maps::RegisterMap;
    use drive_core::state::ProgramKind;
    for id in 0..8 {
        let kind = Maps::by_id(id).program_kind();
        assert_eq!(kind != ProgramKind::None, Maps::has_program_id(id), "0x2190 = {id}");
    }
    assert_eq!(Maps::cls9().program_kind(), ProgramKind::Segments);
    assert_eq!(Maps::servo().program_kind(), ProgramKind::Groups);
}
