//! Modbus ASCII framing: seed 004's lines byte for byte both ways, the limits, and properties of
//! the receiver over any ADU, corruption, noise and split.

use drive_core::Instant;
use drive_core::ascii::{
    DEFAULT_TIMEOUT_MICROS, Framer, MAX_ADU, MAX_LINE, RxError, encode, encode_in_place, line_len, lrc,
};
use proptest::prelude::*;

/// What a receiver made of some bytes: the ADUs of good frames and the errors, in order.
#[derive(Debug, PartialEq, Eq)]
enum Out {
    Frame(Vec<u8>),
    Error(RxError),
}

/// Feeds `chunks` to `f`, each at its own instant 1 ms after the one before.
fn feed_chunks<'a>(f: &mut Framer, chunks: impl IntoIterator<Item = &'a [u8]>) -> Vec<Out> {
    let mut out = Vec::new();
    for (i, c) in chunks.into_iter().enumerate() {
        f.extend(Instant::from_micros(i as u64 * 1000), c, |r| {
            out.push(match r {
                Ok(adu) => Out::Frame(adu.to_vec()),
                Err(e) => Out::Error(e),
            })
        });
    }
    out
}

fn feed(bytes: &[u8]) -> Vec<Out> {
    feed_chunks(&mut Framer::default(), [bytes])
}

fn line(adu: &[u8]) -> Vec<u8> {
    let mut out = [0u8; MAX_LINE];
    let n = encode(adu, &mut out).expect("an ADU of 2..=254 bytes");
    out[..n].to_vec()
}

/// Seed 004 §6.3's ASCII lines and the ADUs they carry.
const SEED_004: [(&[u8], &[u8]); 4] = [
    (b":010302000002F8\r\n", &[0x01, 0x03, 0x02, 0x00, 0x00, 0x02]),
    (b":01030400B11F40E8\r\n", &[0x01, 0x03, 0x04, 0x00, 0xB1, 0x1F, 0x40]),
    (b":01060200006493\r\n", &[0x01, 0x06, 0x02, 0x00, 0x00, 0x64]),
    (b":010302010001F8\r\n", &[0x01, 0x03, 0x02, 0x01, 0x00, 0x01]),
];

#[test]
fn seed_004_lines_both_ways() {
    for (text, adu) in SEED_004 {
        assert_eq!(line(adu), text, "{adu:02X?} encoded");
        assert_eq!(feed(text), [Out::Frame(adu.to_vec())], "{}", String::from_utf8_lossy(text));
    }
    // The manual's LRC figures.
    assert_eq!(lrc(&[0x01, 0x03, 0x02, 0x01, 0x00, 0x01]), 0xF8);
    assert_eq!(lrc(&[0x01, 0x06, 0x02, 0x00, 0x00, 0x64]), 0x93);
}

#[test]
fn the_longest_line_is_513_characters() {
    assert_eq!(MAX_LINE, 513);
    let adu = [0x5Au8; MAX_ADU];
    let l = line(&adu);
    assert_eq!(l.len(), 513);
    assert_eq!(feed(&l), [Out::Frame(adu.to_vec())]);
    // One byte more is refused by the encoder and overruns the receiver at its 511th digit; the
    // rest of the line is noise.
    assert_eq!(encode(&[0; MAX_ADU + 1], &mut [0u8; 1024]), None);
    let mut long = b":".to_vec();
    long.extend(std::iter::repeat_n(b'0', 2 * (MAX_ADU + 2)));
    long.extend(b"\r\n");
    assert_eq!(feed(&long), [Out::Error(RxError::Overrun)]);
}

#[test]
fn encode_needs_room_and_an_address_and_function() {
    let mut out = [0u8; 16];
    assert_eq!(encode(&[1], &mut out), None);
    assert_eq!(encode(&[1, 3], &mut out[..8]), None);
    assert_eq!(encode(&[1, 3], &mut out[..9]), Some(line_len(2)));
    assert_eq!(&out[..9], b":0103FC\r\n");
}

#[test]
fn noise_between_lines_and_a_lost_lf() {
    let mut stream = b"\r\n\x00garbage 12 \xFF".to_vec();
    stream.extend(SEED_004[0].0);
    stream.extend(b"\n\n  ");
    // A line whose LF was lost: the next `:` restarts.
    stream.extend(&SEED_004[1].0[..SEED_004[1].0.len() - 1]);
    stream.extend(SEED_004[2].0);
    assert_eq!(
        feed(&stream),
        [Out::Frame(SEED_004[0].1.to_vec()), Out::Error(RxError::Restart), Out::Frame(SEED_004[2].1.to_vec())]
    );
}

#[test]
fn the_timeout_is_a_parameter() {
    let text = SEED_004[0].0;
    for (timeout, gap, ok) in [
        (DEFAULT_TIMEOUT_MICROS, 1_000_000, true),
        (DEFAULT_TIMEOUT_MICROS, 1_000_001, false),
        (500, 500, true),
        (500, 501, false),
    ] {
        let mut f = Framer::new(timeout);
        let mut out = Vec::new();
        f.extend(Instant::from_micros(0), &text[..5], |r| out.push(r.map(<[u8]>::to_vec)));
        f.extend(Instant::from_micros(gap), &text[5..], |r| out.push(r.map(<[u8]>::to_vec)));
        let expected = if ok { Ok(SEED_004[0].1.to_vec()) } else { Err(RxError::Timeout) };
        assert_eq!(out, [expected], "timeout {timeout}, gap {gap}");
    }
}

#[test]
fn encode_in_place_needs_room_and_an_address_and_function() {
    let mut buf = [7u8; 16];
    assert_eq!(encode_in_place(&mut buf, 1), None);
    assert_eq!(encode_in_place(&mut buf, MAX_ADU + 1), None);
    buf[..2].copy_from_slice(&[1, 3]);
    assert_eq!(encode_in_place(&mut buf[..8], 2), None);
    assert_eq!(&buf[..3], &[1, 3, 7], "a refusal changes nothing");
    assert_eq!(encode_in_place(&mut buf[..9], 2), Some(line_len(2)));
    assert_eq!(&buf[..9], b":0103FC\r\n");
    // The longest ADU fills the longest line.
    let mut buf = [0x5Au8; MAX_LINE];
    assert_eq!(encode_in_place(&mut buf, MAX_ADU), Some(MAX_LINE));
    assert_eq!(buf.to_vec(), line(&[0x5A; MAX_ADU]));
}

#[test]
fn a_line_that_ended_is_kept_until_the_next_colon() {
    let mut f = Framer::default();
    let t = Instant::from_micros(5);
    assert_eq!(f.ended(), None);
    // A good line: its bytes with the LRC, and when its last byte came.
    f.extend(t, SEED_004[0].0, |_| {});
    let mut kept = SEED_004[0].1.to_vec();
    kept.push(0xF8);
    assert_eq!(f.ended(), Some((&kept[..], t)));
    assert!(!f.in_frame());
    // Noise after it keeps it (and its time moves on); a `:` forgets it.
    let later = Instant::from_micros(9);
    f.extend(later, b"\r\n x", |_| {});
    assert_eq!(f.ended(), Some((&kept[..], later)));
    f.extend(later, b":", |_| {});
    assert_eq!(f.ended(), None);
    // A line with a bad LRC is kept too (its bytes do not sum to 0); any other verdict is not.
    f.extend(t, b":010302000002F9\r\n", |_| {});
    assert_eq!(f.ended().map(|(b, _)| lrc(b) != 0), Some(true));
    for bad in [&b":0103020000002F8\r\n"[..], b":01FE\r\n", b":0103X\r\n", b":0103\r\r"] {
        f.extend(t, bad, |_| {});
        assert_eq!(f.ended(), None, "{}", String::from_utf8_lossy(bad));
    }
    // Nor after `clear`.
    f.extend(t, SEED_004[1].0, |_| {});
    assert!(f.ended().is_some());
    f.clear();
    assert_eq!(f.ended(), None);
}

/// Any ADU the spec allows: an address, a function code and up to 252 data bytes.
fn adu() -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(any::<u8>(), 2..=MAX_ADU)
}

/// Noise between lines: anything but `:`.
fn noise() -> impl Strategy<Value = Vec<u8>> {
    prop::collection::vec(any::<u8>().prop_filter("not a start", |&b| b != b':'), 0..40)
}

proptest! {
    #[test]
    fn encode_in_place_is_encode(adu in adu(), junk in any::<u8>()) {
        let mut buf = vec![junk; MAX_LINE + 3];
        buf[..adu.len()].copy_from_slice(&adu);
        let n = encode_in_place(&mut buf, adu.len());
        prop_assert_eq!(n, Some(line_len(adu.len())));
        prop_assert_eq!(&buf[..line_len(adu.len())], &line(&adu)[..]);
        // Nothing after the line is touched.
        prop_assert!(buf[line_len(adu.len())..].iter().all(|&b| b == junk));
    }

    #[test]
    fn encode_then_decode_gives_the_adu(adu in adu(), lower in any::<bool>()) {
        let mut l = line(&adu);
        prop_assert_eq!(l.len(), line_len(adu.len()));
        prop_assert!(l[1..l.len() - 2].iter().all(|c| c.is_ascii_digit() || (b'A'..=b'F').contains(c)));
        if lower {
            l.make_ascii_lowercase();
        }
        prop_assert_eq!(feed(&l), [Out::Frame(adu)]);
    }

    #[test]
    fn a_corrupted_character_is_never_taken(adu in adu(), at in any::<prop::sample::Index>(), to in any::<u8>()) {
        let good = line(&adu);
        let at = at.index(good.len());
        let was = good[at];
        // The same digit in the other case is the same character to the receiver.
        prop_assume!(to != was && !to.eq_ignore_ascii_case(&was));
        let mut bad = good.clone();
        bad[at] = to;
        let out = feed(&bad);
        prop_assert!(!out.contains(&Out::Frame(adu.clone())), "{:?} decoded", String::from_utf8_lossy(&bad));
        if to != b':' {
            // Only a `:` can start another frame in the rest of the line.
            prop_assert!(out.iter().all(|o| matches!(o, Out::Error(_))), "{:?}: {:?}", String::from_utf8_lossy(&bad), out);
        }
        // Every corrupted line is reported, but a lost `:` (then the line is noise).
        prop_assert_eq!(out.is_empty(), at == 0);
    }

    #[test]
    fn noise_between_frames_never_makes_a_frame(frames in prop::collection::vec((noise(), adu()), 0..6), tail in noise()) {
        let mut stream = Vec::new();
        for (n, a) in &frames {
            stream.extend(n);
            stream.extend(line(a));
        }
        stream.extend(&tail);
        let expected: Vec<Out> = frames.iter().map(|(_, a)| Out::Frame(a.clone())).collect();
        prop_assert_eq!(feed(&stream), expected);
        prop_assert!(feed(&tail).is_empty());
    }

    #[test]
    fn a_frame_split_anywhere_decodes_the_same(adu in adu(), cuts in prop::collection::vec(any::<prop::sample::Index>(), 0..4)) {
        let l = line(&adu);
        let mut cuts: Vec<usize> = cuts.iter().map(|c| c.index(l.len() + 1)).collect();
        cuts.sort_unstable();
        let mut parts = Vec::new();
        let mut from = 0;
        for c in cuts.into_iter().chain([l.len()]) {
            parts.push(&l[from..c]);
            from = c;
        }
        prop_assert_eq!(feed_chunks(&mut Framer::default(), parts), feed(&l));
        // Byte by byte too.
        prop_assert_eq!(feed_chunks(&mut Framer::default(), l.chunks(1)), [Out::Frame(adu)]);
    }

    #[test]
    fn a_colon_mid_frame_resynchronises(first in adu(), at in any::<prop::sample::Index>(), second in adu()) {
        let broken = line(&first);
        // Cut inside the frame: after its `:`, before its LF (after its CR at the latest).
        let at = 1 + at.index(broken.len() - 1);
        let mut stream = broken[..at].to_vec();
        stream.extend(line(&second));
        prop_assert_eq!(feed(&stream), [Out::Error(RxError::Restart), Out::Frame(second)]);
    }
}
