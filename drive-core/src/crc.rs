//! CRC-16/MODBUS (poly 0x8005 reflected, init 0xFFFF), sent low byte first.

use crc::{CRC_16_MODBUS, Crc, Table};

/// One 512-byte table: the size/speed trade that suits a microcontroller.
pub const MODBUS: Crc<u16, Table<1>> = Crc::<u16, Table<1>>::new(&CRC_16_MODBUS);

/// CRC-16/MODBUS of `bytes`.
///
/// ```
/// assert_eq!(drive_core::crc::crc16(&[0x01, 0x03, 0x60, 0x0C, 0x00, 0x02]), 0x081A);
/// ```
pub fn crc16(bytes: &[u8]) -> u16 {
    update_bytes(INIT, bytes)
}

/// The CRC register `crc` after `bytes`: from [`INIT`], their CRC; from the register after a
/// frame's first bytes, the CRC of the frame.
///
/// ```
/// use drive_core::crc::{INIT, crc16, update, update_bytes};
/// let frame = [0x01, 0x03, 0x60, 0x0C, 0x00, 0x02];
/// assert_eq!(update_bytes(update(INIT, 0x01), &frame[1..]), crc16(&frame));
/// ```
// Always inlined, in plain loops: the slave seals every reply with it on the request path, where
// a call (or a call of `Iterator::fold`) costs more than a short reply's CRC.
#[inline(always)]
pub fn update_bytes(crc: u16, bytes: &[u8]) -> u16 {
    // Two bytes a turn over the crate's table: half the loop's overhead for a few bytes of code,
    // what a long reply (a read of 125 registers) spends most of its CRC on.
    let (pairs, rest) = bytes.as_chunks::<2>();
    let mut crc = crc;
    for &[a, b] in pairs {
        crc = update(update(crc, a), b);
    }
    for &b in rest {
        crc = update(crc, b);
    }
    crc
}

/// Whether `frame` ends in the CRC of the bytes before it (low byte first).
pub fn frame_ok(frame: &[u8]) -> bool {
    match frame.split_last_chunk::<2>() {
        Some((body, crc)) if !body.is_empty() => crc16(body) == u16::from_le_bytes(*crc),
        _ => false,
    }
}

/// The CRC register after one more byte. Start from [`INIT`]; after the last byte the register is
/// the CRC, and after a frame's own CRC (low byte first) it is 0.
///
/// ```
/// use drive_core::crc::{INIT, update};
/// let frame = [0x01, 0x03, 0x60, 0x0C, 0x00, 0x02, 0x1A, 0x08];
/// assert_eq!(frame[..6].iter().fold(INIT, |c, &b| update(c, b)), 0x081A);
/// assert_eq!(frame.iter().fold(INIT, |c, &b| update(c, b)), 0);
/// ```
#[inline]
pub fn update(crc: u16, byte: u8) -> u16 {
    let table = &MODBUS.table()[0];
    table.get(usize::from(crc as u8 ^ byte)).copied().unwrap_or(0) ^ (crc >> 8)
}

/// The CRC register before the first byte.
pub const INIT: u16 = 0xFFFF;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_bytes_a_turn_is_the_crates_checksum_at_every_length() {
        let mut bytes = [0u8; 257];
        for (i, b) in (0u32..).zip(bytes.iter_mut()) {
            *b = (i.wrapping_mul(2_654_435_761) >> 13) as u8;
        }
        for n in 0..=bytes.len() {
            let b = bytes.get(..n).unwrap_or_default();
            assert_eq!(crc16(b), MODBUS.checksum(b), "{n} bytes");
        }
    }
}
