//! Framing by line silence: split frames, gaps, back-to-back frames, noise, broadcast.

mod common;
use common::{Bus, frame, reply};
use drive_core::od::Obj;
use drive_core::{Baud, Drive, DriveConfig};

const READ: [u8; 6] = [0x01, 0x03, 0x60, 0x0C, 0x00, 0x01];
const T15: u64 = 1718; // 9600 baud
const T35: u64 = 4010;

#[test]
fn frame_split_across_reads_within_t15() {
    let mut bus = Bus::factory();
    let f = frame(&READ);
    for chunk in f.chunks(3) {
        bus.send(chunk);
        assert!(bus.wait(T15).is_empty(), "no answer inside the frame");
    }
    assert_eq!(bus.wait(T35), vec![frame(&[0x01, 0x03, 0x02, 0x00, 0x00])]);
}

#[test]
fn reply_waits_for_t35_of_silence() {
    let mut bus = Bus::factory();
    bus.send(&frame(&READ));
    assert!(bus.wait(T35 - 1).is_empty());
    assert_eq!(bus.wait(1).len(), 1);
}

#[test]
fn gap_over_t15_inside_a_frame_discards_it() {
    let mut bus = Bus::factory();
    let f = frame(&READ);
    bus.send(&f[..4]);
    bus.wait(T15 + 1);
    bus.send(&f[4..]);
    assert!(bus.wait(20_000).is_empty());
    assert_eq!(bus.drive.counters().bus_errors, 1);
    // The line recovers: the next frame is answered.
    assert!(bus.request(&READ).is_some());
}

#[test]
fn back_to_back_frames_separated_by_t35() {
    let mut bus = Bus::factory();
    bus.send(&frame(&[0x01, 0x06, 0x60, 0x08, 0x01, 0x00]));
    bus.now += T35; // exactly t3.5 later, with no timer call in between
    bus.send(&frame(&[0x01, 0x06, 0x60, 0x09, 0x02, 0x00]));
    let replies = {
        let mut r: Vec<_> = bus.drive.take_reply().map(<[u8]>::to_vec).into_iter().collect();
        r.extend(bus.wait(T35));
        r
    };
    assert_eq!(replies.len(), 2);
    assert_eq!((bus.drive.state().read(Obj::StartSpeed), bus.drive.state().read(Obj::StopSpeed)), (256, 512));
}

#[test]
fn two_frames_without_silence_are_one_bad_frame() {
    let mut bus = Bus::factory();
    let mut both = frame(&READ);
    both.extend(frame(&READ));
    bus.send(&both);
    assert!(bus.wait(20_000).is_empty());
}

#[test]
fn noise_before_a_frame() {
    let mut bus = Bus::factory();
    // Noise followed by t3.5 of silence is a frame of its own, dropped for its CRC.
    bus.send(&[0xFF, 0x00, 0x13]);
    assert!(bus.wait(T35).is_empty());
    assert_eq!(bus.request(&READ), reply(&[0x01, 0x03, 0x02, 0x00, 0x00]));
    // Noise glued to the frame spoils it.
    bus.send(&[0x55]);
    bus.send(&frame(&READ));
    assert!(bus.wait(20_000).is_empty());
    assert_eq!(bus.drive.counters().bus_errors, 2);
}

#[test]
fn broadcast_writes_execute_and_are_not_answered() {
    let mut bus = Bus::factory();
    assert_eq!(bus.request(&[0x00, 0x06, 0x60, 0x0C, 0x00, 0x10]), None);
    assert_eq!(bus.request(&[0x00, 0x10, 0x60, 0x08, 0x00, 0x02, 0x04, 0x01, 0x00, 0x02, 0x00]), None);
    let st = bus.drive.state();
    assert_eq!((st.read(Obj::Microsteps), st.read(Obj::StartSpeed), st.read(Obj::StopSpeed)), (16, 256, 512));
    // A broadcast that would be an exception is silent too, and changes nothing.
    assert_eq!(bus.request(&[0x00, 0x06, 0x60, 0x0C, 0x01, 0x01]), None);
    assert_eq!(bus.drive.state().read(Obj::Microsteps), 16);
    assert_eq!(bus.drive.counters().no_responses, 3);
}

#[test]
fn timing_follows_the_baud_rate() {
    let fast = Drive::new(DriveConfig { baud: Baud::new(115_200), ..Default::default() });
    let mut bus = Bus::new(fast);
    bus.send(&frame(&READ));
    assert!(bus.wait(1749).is_empty());
    assert_eq!(bus.wait(1).len(), 1);
    assert_eq!(bus.drive.state().read(Obj::BaudRate), 115_200);
}

#[test]
fn address_comes_from_the_node_id() {
    let mut bus = Bus::new(Drive::new(DriveConfig { address: drive_core::SlaveAddr::new(7), ..Default::default() }));
    assert_eq!(bus.request(&READ), None);
    assert_eq!(bus.request(&[0x07, 0x03, 0x20, 0x28, 0x00, 0x01]), reply(&[0x07, 0x03, 0x02, 0x00, 0x07]));
    // A new node id takes effect at the next power-up, so a typo cannot lose the drive.
    assert!(bus.request(&[0x07, 0x06, 0x20, 0x28, 0x00, 0x09]).is_some());
    assert_eq!(bus.request(&[0x07, 0x03, 0x20, 0x28, 0x00, 0x01]), reply(&[0x07, 0x03, 0x02, 0x00, 0x09]));
}

/// Found by the fuzzing of the framer: a receive call with no bytes moved the end of the frame's
/// silence (and could mark a gap), as if a byte had arrived.
#[test]
fn a_receive_of_no_bytes_changes_nothing() {
    use drive_core::Instant;
    use drive_core::rtu::Framer;
    let Some(baud) = Baud::new(9600) else { panic!("9600 baud") };
    let mut framer = Framer::new(baud);
    framer.extend(Instant::from_micros(0), &[1, 3]);
    let deadline = framer.deadline();
    // Past t1.5 and nearly t3.5: an empty call must neither mark a gap nor restart the silence.
    framer.extend(Instant::from_micros(3_000), &[]);
    assert_eq!(framer.deadline(), deadline);
    assert_eq!(framer.frame(), (&[1u8, 3][..], None));
    assert!(framer.ended(Instant::from_micros(4_100)));
}
