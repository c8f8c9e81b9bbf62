//! Any byte stream at any timing: the drive never panics, and every reply is a well-formed frame
//! with a valid CRC that answers, in order, a valid request to the drive's address.

mod common;
use common::frame;
use drive_core::{Drive, Instant, crc};
use proptest::prelude::*;

const T15: u64 = 1718;
const T35: u64 = 4010;

/// A chunk of bytes arriving together after a silence.
#[derive(Clone, Debug)]
struct Chunk {
    gap: u64,
    bytes: Vec<u8>,
}

fn gap() -> impl Strategy<Value = u64> {
    prop_oneof![Just(0u64), 1..T15, Just(T15), Just(T15 + 1), T15..T35, Just(T35 - 1), Just(T35), T35..100_000]
}

/// A well-formed request (valid CRC) to address 0-2, with plausible or random contents.
fn request() -> impl Strategy<Value = Vec<u8>> {
    let function =
        prop_oneof![Just(0x03u8), Just(0x04), Just(0x06), Just(0x10), Just(0x17), Just(0x08), Just(0x2B), any::<u8>()];
    let register = prop_oneof![0x6000u16..0x6090, 0x2000u16..0x2110, 0x1018u16..0x1028, any::<u16>()];
    (0u8..3, function, register, prop::collection::vec(any::<u8>(), 0..24)).prop_map(|(addr, f, reg, mut data)| {
        if f == 0x08 && data.len() >= 2 {
            data[0] = 0;
            if data[1] == 0x04 {
                data[1] = 0x0B; // listen-only mode would silence the rest of the stream
            }
        }
        let mut body = vec![addr, f, (reg >> 8) as u8, reg as u8];
        body.extend(data);
        frame(&body)
    })
}

fn chunk() -> impl Strategy<Value = Chunk> {
    let bytes =
        prop_oneof![request(), prop::collection::vec(any::<u8>(), 1..40), prop::collection::vec(any::<u8>(), 250..300)];
    (gap(), bytes).prop_map(|(gap, bytes)| Chunk { gap, bytes })
}

/// The frames a correct receiver assembles from the chunks: (bytes, spoilt by a gap).
fn reference_frames(chunks: &[Chunk]) -> Vec<(Vec<u8>, bool)> {
    let mut frames: Vec<(Vec<u8>, bool)> = Vec::new();
    for c in chunks {
        match frames.last_mut() {
            Some(last) if c.gap < T35 => {
                last.1 |= c.gap > T15;
                last.0.extend(&c.bytes);
            }
            _ => frames.push((c.bytes.clone(), false)),
        }
    }
    frames
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

    #[test]
    fn replies_answer_valid_requests(chunks in prop::collection::vec(chunk(), 1..30), use_timer in any::<bool>()) {
        let mut drive = Drive::factory();
        let mut now = 1_000u64;
        let mut replies: Vec<Vec<u8>> = Vec::new();
        for c in &chunks {
            let next = now + c.gap;
            if let Some(d) = drive.deadline().filter(|d| use_timer && d.as_micros() <= next) {
                drive.on_timer(d);
                replies.extend(drive.take_reply().map(<[u8]>::to_vec));
            }
            now = next;
            drive.on_rx(Instant::from_micros(now), &c.bytes);
            replies.extend(drive.take_reply().map(<[u8]>::to_vec));
        }
        drive.on_timer(Instant::from_micros(now + T35));
        replies.extend(drive.take_reply().map(<[u8]>::to_vec));

        let answered: Vec<Vec<u8>> = reference_frames(&chunks)
            .into_iter()
            .filter(|(f, spoilt)| !spoilt && f.len() <= 256 && f.len() >= 4 && crc::frame_ok(f) && f[0] == 1 && f[1] < 0x80)
            .map(|(f, _)| f)
            .collect();
        prop_assert_eq!(replies.len(), answered.len(), "one reply per valid request to address 1");
        for (reply, req) in replies.iter().zip(&answered) {
            prop_assert!(reply.len() >= 5 && reply.len() <= 256);
            prop_assert!(crc::frame_ok(reply));
            prop_assert_eq!(reply[0], 1);
            prop_assert_eq!(reply[1] & 0x7F, req[1]);
            if reply[1] & 0x80 != 0 {
                prop_assert_eq!(reply.len(), 5);
                prop_assert!((1..=4).contains(&reply[2]));
            }
        }
    }
}
