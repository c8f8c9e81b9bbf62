//! The input debouncer of the external stops (0x6042) and the inputs (0x21F9-0x21FF), and the
//! pins' setup, by property.

use drive_core::Instant;
use drive_core::controller::io::{Debouncer, PinConfig, PinMode};
use proptest::prelude::*;

/// One tick, µs.
const TICK: u64 = 50;

/// Feeds `levels` a tick apart (the position is the tick's number); the ticks at which an edge
/// to `active` was confirmed, with the position it reports.
fn confirmations(levels: &[bool], active: bool, delay_ticks: u64) -> Vec<(usize, i64)> {
    let mut d = Debouncer::default();
    let mut out = Vec::new();
    for (k, &level) in levels.iter().enumerate() {
        let now = Instant::from_micros(k as u64 * TICK);
        let edge = d.update(now, level, (delay_ticks * TICK) as u32, k as i64);
        if let Some(e) = edge.filter(|e| e.rising == active) {
            out.push((k, e.at));
        }
    }
    out
}

proptest! {
    /// Active pulses shorter than the delay never count, however many, when each is over
    /// before the next starts the delay again (the level is read once, the delay after an edge).
    #[test]
    fn pulses_shorter_than_the_delay_never_count(
        delay in 2u64..200,
        runs in proptest::collection::vec((1u64..1000, 0.0f64..1.0), 1..20),
        active: bool,
    ) {
        let mut levels = vec![!active];
        for (gap, share) in runs {
            let pulse = ((delay - 1) as f64 * share) as u64 + 1;
            levels.extend(std::iter::repeat_n(active, pulse.min(delay - 1) as usize));
            levels.extend(std::iter::repeat_n(!active, (gap + delay) as usize));
        }
        prop_assert!(confirmations(&levels, active, delay).is_empty());
    }

    /// An edge followed by bounces shorter than the delay, then the active level held, counts
    /// once, exactly the delay after the edge, with the position at the edge.
    #[test]
    fn a_bouncing_edge_counts_once_after_the_delay(
        delay in 0u64..200,
        idle in 1usize..50,
        bounces in proptest::collection::vec(any::<bool>(), 0..200),
        active: bool,
    ) {
        let bounce: Vec<bool> = bounces.iter().take(delay.saturating_sub(1) as usize).map(|&b| b == active).collect();
        let mut levels = vec![!active; idle];
        levels.push(active);
        levels.extend(bounce.iter().map(|&b| if b { active } else { !active }));
        levels.resize(levels.len().max(idle + delay as usize + 1), active);
        levels.extend(std::iter::repeat_n(active, 500));
        prop_assert_eq!(confirmations(&levels, active, delay), vec![(idle + delay as usize, idle as i64)]);
    }
}

#[test]
fn the_first_reading_is_no_edge() {
    assert!(confirmations(&[true; 100], true, 0).is_empty());
    assert_eq!(confirmations(&[false, true, true], true, 0), vec![(1, 1)]);
}

#[test]
fn enabled_ext_inputs_take_the_pulls_of_0x6015_and_the_rest_of_0x602f() {
    // EXT2 (bit 1 of 0x6013) enabled: type 0 pulls a rising edge down, type 1 up.
    assert_eq!(PinConfig::new(0, 0, 2, 2, false).mode(8), PinMode::PullDown);
    assert_eq!(PinConfig::new(0, 0, 2, 2, true).mode(8), PinMode::PullUp);
    assert_eq!(PinConfig::new(0, 0, 2, 0, true).mode(8), PinMode::PullDown);
    // Disabled: 0x602F's field (EXT2 in bits 17-16), here analog.
    assert_eq!(PinConfig::new(0, 3 << 16, 0, 0, false).mode(8), PinMode::Analog);
    // EXT pins cannot be outputs.
    assert_eq!(PinConfig::new(0xFFFF, 0, 0, 0, false).outputs, 0x087F);
}
