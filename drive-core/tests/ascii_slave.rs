//! The slave in Modbus ASCII (0x2192 = 1 at power-up): seed 004's lines byte for byte, the
//! native map's requests and replies as lines whose LRCs are computed here, exceptions,
//! broadcasts, noise, the inter-character timeout, the counters, listen-only mode, and the same
//! replies as RTU for any request.

use std::borrow::Borrow;

use drive_core::controller::Shared;
use drive_core::drive::{Counters, LineFraming};
use drive_core::maps::{Maps, RegisterMap};
use drive_core::od::Obj;
use drive_core::pdu::{Exception, Words};
use drive_core::state::ProgramMemory;
use drive_core::{Drive, DriveConfig, DriveState, Instant, Params, crc};
use proptest::prelude::*;

/// The spec's inter-character timeout, µs.
const TIMEOUT: u64 = 1_000_000;

/// The LRC of `bytes`, from the spec: the two's complement of their sum modulo 256.
fn lrc(bytes: &[u8]) -> u8 {
    (0x100 - bytes.iter().map(|&b| u32::from(b)).sum::<u32>() % 0x100) as u8
}

/// The line that carries `adu`: `:`, upper-case hex of the ADU and its LRC, CR LF.
fn line(adu: &[u8]) -> Vec<u8> {
    let mut text = String::from(":");
    for b in adu.iter().chain([lrc(adu)].iter()) {
        text.push_str(&format!("{b:02X}"));
    }
    text.push_str("\r\n");
    text.into_bytes()
}

/// The ADU a reply line carries, checked to be well formed: `:`, upper-case hex digits of an
/// even count, an LRC that matches, CR LF.
fn adu_of(reply: &[u8]) -> Vec<u8> {
    let text = std::str::from_utf8(reply).unwrap_or_else(|_| panic!("not text: {reply:02X?}"));
    let hex = text.strip_prefix(':').and_then(|t| t.strip_suffix("\r\n")).unwrap_or_else(|| panic!("{text:?}"));
    assert!(hex.len().is_multiple_of(2) && hex.len() >= 6, "{text:?}");
    assert!(hex.bytes().all(|c| c.is_ascii_digit() || (b'A'..=b'F').contains(&c)), "{text:?}");
    let bytes: Vec<u8> = (0..hex.len()).step_by(2).map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap()).collect();
    let (check, adu) = bytes.split_last().unwrap();
    assert_eq!(lrc(adu), *check, "{text:?}");
    adu.to_vec()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Saved parameters with the line framing `value` (0x2192).
fn params(value: u32) -> Params {
    let mut p = Params::factory();
    assert!(p.set(Obj::LineFraming, value));
    p
}

mod common;

/// A drive on a line with a clock the test moves.
type Rig<M> = common::Bus<M>;

impl<M: RegisterMap> Rig<M> {
    /// Bytes arriving together now; the reply they let out, if any (a line that had ended
    /// before them is served first).
    fn rx(&mut self, bytes: &[u8]) -> Option<Vec<u8>> {
        self.send(bytes);
        self.drive.take_reply().map(<[u8]>::to_vec)
    }

    /// Sends `bytes` and lets 10 ms pass: the one reply, if any.
    fn exchange(&mut self, bytes: &[u8]) -> Option<Vec<u8>> {
        let mut replies: Vec<_> = self.rx(bytes).into_iter().collect();
        replies.extend(self.wait(10_000));
        assert!(
            replies.len() <= 1,
            "one request, at most one reply: {:?}",
            replies.iter().map(|r| text(r)).collect::<Vec<_>>()
        );
        replies.pop()
    }

    fn counters(&self) -> Counters {
        *self.drive.counters()
    }
}

/// A factory drive with the native map, in ASCII.
fn ascii_native() -> Rig<drive_core::maps::NativeMap> {
    let drive = Drive::boot(DriveConfig::default(), &params(1), 0);
    assert_eq!(drive.line_framing(), LineFraming::Ascii);
    Rig::new(drive)
}

/// Seed 004's two registers of its manual's examples, 0x0200 and 0x0201 (until the servo map
/// is here): reads and writes of them alone.
#[derive(Clone, Debug)]
struct ManualRegisters {
    regs: [u16; 2],
}

impl ManualRegisters {
    fn slot(addr: u16, qty: usize) -> Result<usize, Exception> {
        let i = usize::from(addr.wrapping_sub(0x0200));
        if i + qty <= 2 && qty > 0 { Ok(i) } else { Err(Exception::IllegalDataAddress) }
    }
}

impl RegisterMap for ManualRegisters {
    fn read<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        _drive: &DriveState<P, G>,
        addr: u16,
        out: &mut [u8],
    ) -> Result<(), Exception> {
        let i = Self::slot(addr, out.len() / 2)?;
        for (w, v) in out.chunks_mut(2).zip(&self.regs[i..]) {
            w.copy_from_slice(&v.to_be_bytes());
        }
        Ok(())
    }

    fn check_read(&self, addr: u16, qty: u16) -> Result<(), Exception> {
        Self::slot(addr, usize::from(qty)).map(|_| ())
    }

    fn write<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &mut self,
        _drive: &mut DriveState<P, G>,
        addr: u16,
        values: Words<'_>,
    ) -> Result<(), Exception> {
        let i = Self::slot(addr, values.len())?;
        for (r, v) in self.regs[i..].iter_mut().zip(values.iter()) {
            *r = v;
        }
        Ok(())
    }
}

#[test]
fn seed_004_manual_lines_byte_for_byte() {
    let map = ManualRegisters { regs: [0x00B1, 0x1F40] };
    let mut rig = Rig::new(Drive::boot_with_map(DriveConfig::default(), map, &params(1), 0));
    // §6.3: read 2 registers from 0200h; the answer 00B1h, 1F40h.
    assert_eq!(rig.exchange(b":010302000002F8\r\n").as_deref(), Some(&b":01030400B11F40E8\r\n"[..]));
    // Write 0064h to 0200h: the answer is the request.
    assert_eq!(rig.exchange(b":01060200006493\r\n").as_deref(), Some(&b":01060200006493\r\n"[..]));
    // Read 1 register from 0201h.
    assert_eq!(rig.exchange(b":010302010001F8\r\n"), Some(line(&[0x01, 0x03, 0x02, 0x1F, 0x40])));
    assert_eq!(rig.exchange(b":010302000001F9\r\n"), Some(line(&[0x01, 0x03, 0x02, 0x00, 0x64])));
    assert_eq!(rig.drive.map().regs, [0x0064, 0x1F40]);
}

#[test]
fn seed_004_lines_through_the_servo_map() {
    // P□600 = 31h (ASCII 8N1, 9600) written in RTU: stored, in force after a restart.
    let mut rtu = Rig::new(Drive::with_map(DriveConfig::default(), Maps::servo()));
    let body = [0x01, 0x06, 0x02, 0x58, 0x00, 0x31];
    let mut frame = body.to_vec();
    frame.extend(crc::crc16(&body).to_le_bytes());
    assert_eq!(rtu.exchange(&frame), Some(frame.clone()));
    assert_eq!(rtu.drive.state().read(Obj::LineFraming), 1);
    assert_eq!(rtu.drive.line_framing(), LineFraming::Rtu);
    let saved = rtu.drive.state().params();
    let mut rig = Rig::new(Drive::boot_with_map(DriveConfig::default(), Maps::servo(), &saved, 0));
    assert_eq!(rig.drive.line_framing(), LineFraming::Ascii);
    // §6.3's lines. P□512 and P□513 (the signal allocation) read 0 from the factory: no
    // signal on an input (the manual's 00B1h and 1F40h name terminals this drive does not have:
    // `seed_004_manual_lines_byte_for_byte` has them). The write 0064h puts /START-HOME on IN4
    // and /POS-START on IN6, and its answer echoes it.
    assert_eq!(rig.exchange(b":010302000002F8\r\n").as_deref(), Some(&b":01030400000000F8\r\n"[..]));
    assert_eq!(rig.exchange(b":01060200006493\r\n").as_deref(), Some(&b":01060200006493\r\n"[..]));
    assert_eq!(rig.drive.state().read(Obj::InputFunction4), 12);
    assert_eq!(rig.drive.state().read(Obj::InputFunction6), 16);
    assert_eq!(rig.exchange(b":010302010001F8\r\n").as_deref(), Some(&b":0103020000FA\r\n"[..]));
    // P□600 reads 31h: 01+03+02+00+31 = 37h, LRC C9h.
    assert_eq!(rig.exchange(&line(&[0x01, 0x03, 0x02, 0x58, 0x00, 0x01])).as_deref(), Some(&b":0103020031C9\r\n"[..]));
    // P□602 = 50 (5 s): the answer echoes the request.
    let write = line(&[0x01, 0x06, 0x02, 0x5A, 0x00, 0x32]);
    assert_eq!(rig.exchange(&write), Some(write.clone()));
    assert_eq!(rig.drive.state().read(Obj::CommTimeout), 50);
}

#[test]
fn native_reads_and_writes_as_lines() {
    let mut rig = ascii_native();
    // 0x600C..0x600D: resolution 0, phase current 658 mA (0x0292). 01+03+60+0C+00+02 = 72h,
    // LRC 8Eh; 01+03+04+00+00+02+92 = 9Ch, LRC 64h.
    assert_eq!(rig.exchange(b":0103600C00028E\r\n").as_deref(), Some(&b":0103040000029264\r\n"[..]));
    // 0x6008 (start speed, 600 from the factory) = 800: 01+06+60+08+03+20 = 92h, LRC 6Eh; the
    // answer echoes it.
    assert_eq!(rig.exchange(b":0106600803206E\r\n").as_deref(), Some(&b":0106600803206E\r\n"[..]));
    assert_eq!(rig.drive.state().read(Obj::StartSpeed), 800);
    // Read back: 01+03+60+08+00+01 = 6Dh, LRC 93h; 01+03+02+03+20 = 29h, LRC D7h.
    assert_eq!(rig.exchange(b":01036008000193\r\n").as_deref(), Some(&b":0103020320D7\r\n"[..]));
    // 0x10 of two registers (0x6008 = 700, 0x6009 = 0x0190): the answer is address and count.
    let req = [0x01, 0x10, 0x60, 0x08, 0x00, 0x02, 0x04, 0x02, 0xBC, 0x01, 0x90];
    assert_eq!(rig.exchange(&line(&req)), Some(line(&[0x01, 0x10, 0x60, 0x08, 0x00, 0x02])));
    assert_eq!(rig.drive.state().read(Obj::StartSpeed), 700);
    let c = rig.counters();
    assert_eq!((c.bus_messages, c.slave_messages, c.bus_errors, c.exceptions, c.no_responses), (4, 4, 0, 0, 0));
}

#[test]
fn lower_case_digits_are_read_and_answered_in_upper_case() {
    let mut rig = ascii_native();
    assert_eq!(rig.exchange(b":0103600c00028e\r\n").as_deref(), Some(&b":0103040000029264\r\n"[..]));
    // A write is answered with its ADU encoded anew, not with its line: 01+06+60+08+02+BC =
    // 12Dh, LRC D3h.
    assert_eq!(rig.exchange(b":0106600802bcd3\r\n").as_deref(), Some(&b":0106600802BCD3\r\n"[..]));
    assert_eq!(rig.exchange(b":0106600802bCd3\r\n").as_deref(), Some(&b":0106600802BCD3\r\n"[..]));
    assert_eq!(rig.drive.state().read(Obj::StartSpeed), 700);
}

#[test]
fn exceptions_are_lines_too() {
    let mut rig = ascii_native();
    // Seed 004's read of 0200h is no native register: 02. 01+83+02 = 86h, LRC 7Ah.
    assert_eq!(rig.exchange(b":010302000002F8\r\n").as_deref(), Some(&b":0183027A\r\n"[..]));
    // Its write too: 01+86+02 = 89h, LRC 77h.
    assert_eq!(rig.exchange(b":01060200006493\r\n").as_deref(), Some(&b":01860277\r\n"[..]));
    // 126 registers: 03. 01+83+03 = 87h, LRC 79h.
    assert_eq!(rig.exchange(&line(&[0x01, 0x03, 0x60, 0x00, 0x00, 0x7E])).as_deref(), Some(&b":01830379\r\n"[..]));
    // An unknown function: 01.
    assert_eq!(rig.exchange(&line(&[0x01, 0x41, 0x00])), Some(line(&[0x01, 0xC1, 0x01])));
    assert_eq!(rig.counters().exceptions, 4);
}

#[test]
fn a_broadcast_acts_and_is_never_answered() {
    let mut rig = ascii_native();
    // 00+06+60+08+02+BC = 12Ch, LRC D4h.
    assert_eq!(rig.exchange(b":0006600802BCD4\r\n"), None);
    assert_eq!(rig.drive.state().read(Obj::StartSpeed), 700);
    // A read broadcast is not executed, nor answered.
    assert_eq!(rig.exchange(&line(&[0x00, 0x03, 0x60, 0x0C, 0x00, 0x02])), None);
    // Another drive's request neither.
    assert_eq!(rig.exchange(&line(&[0x02, 0x03, 0x60, 0x0C, 0x00, 0x02])), None);
    let c = rig.counters();
    assert_eq!((c.bus_messages, c.slave_messages, c.no_responses), (3, 2, 2));
}

#[test]
fn noise_between_lines_is_ignored() {
    let mut rig = ascii_native();
    let mut stream = b"\r\n\x00noise 12 \xFF\n".to_vec();
    stream.extend(b":0103600C00028E\r\n");
    stream.extend(b"\r\n  \x01\x03 more noise");
    assert_eq!(rig.exchange(&stream).as_deref(), Some(&b":0103040000029264\r\n"[..]));
    assert_eq!(rig.exchange(b"noise, no line\r\n"), None);
    let c = rig.counters();
    assert_eq!((c.bus_messages, c.bus_errors), (1, 0));
}

#[test]
fn a_line_broken_by_the_timeout_is_dropped() {
    let mut rig = ascii_native();
    let request = b":0103600C00028E\r\n";
    // One second between two characters is within the timeout.
    assert_eq!(rig.rx(&request[..5]), None);
    let start = rig.now;
    assert_eq!(rig.drive.deadline(), Some(Instant::from_micros(start + TIMEOUT + 1)));
    assert!(rig.wait(TIMEOUT).is_empty());
    assert_eq!(rig.exchange(&request[5..]).as_deref(), Some(&b":0103040000029264\r\n"[..]));
    // A second and a microsecond: the line is dropped at the deadline, and its rest is noise.
    assert_eq!(rig.rx(&request[..5]), None);
    assert!(rig.wait(TIMEOUT + 1).is_empty());
    assert_eq!(rig.drive.deadline(), None);
    assert_eq!(rig.counters().bus_errors, 1);
    assert_eq!(rig.exchange(&request[5..]), None);
    // The same when the timer is late: the next character finds the line timed out.
    assert_eq!(rig.rx(&request[..5]), None);
    rig.now += TIMEOUT + 5;
    assert_eq!(rig.exchange(&request[5..]), None);
    // A `:` after the silence starts the next line.
    assert_eq!(rig.rx(&request[..5]), None);
    rig.now += 2 * TIMEOUT;
    assert_eq!(rig.exchange(request).as_deref(), Some(&b":0103040000029264\r\n"[..]));
    let c = rig.counters();
    assert_eq!((c.bus_messages, c.bus_errors), (2, 3));
}

#[test]
fn a_line_waits_from_its_lf_until_the_timer_or_the_next_bytes() {
    let mut rig = ascii_native();
    let request = b":0103600C00028E\r\n";
    let answer = Some(b":0103040000029264\r\n".to_vec());
    // Ended at its LF: due at once, served by the timer, not inside `on_rx`.
    assert_eq!(rig.rx(request), None);
    let now = Instant::from_micros(rig.now);
    assert!(rig.drive.frame_due(now));
    assert_eq!(rig.drive.deadline(), Some(now));
    assert_eq!(rig.wait(0), [answer.clone().unwrap()]);
    assert!(!rig.drive.frame_due(now));
    assert_eq!(rig.drive.deadline(), None);
    // Or by the next bytes, first.
    assert_eq!(rig.rx(request), None);
    rig.now += 100;
    assert_eq!(rig.rx(b"\r\n"), answer);
    assert_eq!(rig.drive.deadline(), None);
    // Noise after it in the same call leaves it waiting.
    assert_eq!(rig.rx(b":0103600C00028E\r\nnoise"), None);
    assert!(rig.drive.frame_due(Instant::from_micros(rig.now)));
    assert_eq!(rig.wait(0), [answer.clone().unwrap()]);
    // A `:` behind it in the same call serves it before the next line starts, which waits.
    let mut two = request.to_vec();
    two.extend(b"\r\n");
    two.extend(&line(&[0x01, 0x03, 0x60, 0x08, 0x00, 0x01]));
    rig.now += 100;
    assert_eq!(rig.rx(&two), answer);
    assert_eq!(rig.wait(0), [line(&[0x01, 0x03, 0x02, 0x02, 0x58])]);
    assert_eq!(rig.counters().bus_messages, 5);
}

#[test]
fn dropped_lines_are_counted() {
    let mut rig = ascii_native();
    let bad: [&[u8]; 7] = [
        b":0103600C00028F\r\n", // LRC
        b":0103600C0X028E\r\n", // a character that is no hex digit
        b":0103600C00028\r\n",  // odd length
        b":01FE\r\n",           // too short
        b":0103600C00028E\rX",  // CR without LF
        b":0103600C00028E\n",   // LF without CR
        b":0103600C:",          // restart: the first dropped, the second...
    ];
    for l in bad {
        assert_eq!(rig.exchange(l), None, "{}", text(l));
    }
    // ... ended by the timeout.
    assert!(rig.wait(TIMEOUT + 1).is_empty());
    let mut long = b":".to_vec();
    long.extend(std::iter::repeat_n(b'0', 600));
    long.extend(b"\r\n");
    assert_eq!(rig.exchange(&long), None);
    let c = rig.counters();
    assert_eq!((c.bus_messages, c.bus_errors, c.overruns), (0, 8, 1));
    // The counters through function 0x08: bus messages (0x0B), bus errors (0x0C), overruns (0x12).
    assert_eq!(
        rig.exchange(&line(&[0x01, 0x08, 0x00, 0x0C, 0x00, 0x00])),
        Some(line(&[0x01, 0x08, 0x00, 0x0C, 0x00, 8]))
    );
    assert_eq!(
        rig.exchange(&line(&[0x01, 0x08, 0x00, 0x12, 0x00, 0x00])),
        Some(line(&[0x01, 0x08, 0x00, 0x12, 0x00, 1]))
    );
    assert_eq!(
        rig.exchange(&line(&[0x01, 0x08, 0x00, 0x0B, 0x00, 0x00])),
        Some(line(&[0x01, 0x08, 0x00, 0x0B, 0x00, 3]))
    );
}

#[test]
fn an_lrc_error_is_answered_where_the_map_answers_a_crc_error() {
    // EC-57 answers a bad CRC with its code 01 when 0x21D2 = 1; in ASCII a bad LRC.
    let mut p = params(1);
    assert!(p.set(Obj::CrcErrorReply, 1));
    let mut rig = Rig::new(Drive::boot_with_map(DriveConfig::default(), Maps::ec57(), &p, 0));
    let good = line(&[0x01, 0x03, 0x20, 0x00, 0x00, 0x00, 0x04]);
    let mut bad = good.clone();
    let n = bad.len();
    bad[n - 3] = if bad[n - 3] == b'0' { b'1' } else { b'0' };
    assert_eq!(rig.exchange(&bad), Some(line(&[0x01, 0x83, 0x01])));
    assert!(rig.exchange(&good).is_some_and(|r| adu_of(&r)[1] == 0x03));
    // Not to another address, nor a broadcast.
    let mut other = line(&[0x02, 0x03, 0x20, 0x00, 0x00, 0x00, 0x04]);
    other[n - 3] ^= 1;
    assert_eq!(rig.exchange(&other), None);
    assert_eq!(rig.counters().bus_errors, 2);
}

#[test]
fn listen_only_mode_as_in_rtu() {
    let mut rig = ascii_native();
    let read = b":0103600C00028E\r\n";
    assert_eq!(rig.exchange(&line(&[0x01, 0x08, 0x00, 0x04, 0x00, 0x00])), None);
    assert_eq!(rig.exchange(read), None);
    // Restart communications: leaves listen-only mode, unanswered.
    assert_eq!(rig.exchange(&line(&[0x01, 0x08, 0x00, 0x01, 0x00, 0x00])), None);
    assert_eq!(rig.exchange(read).as_deref(), Some(&b":0103040000029264\r\n"[..]));
}

#[test]
fn rtu_frames_are_noise_to_an_ascii_drive_and_lines_to_an_rtu_drive() {
    let rtu_read = [0x01, 0x03, 0x60, 0x0C, 0x00, 0x02, 0x1A, 0x08];
    let mut ascii = ascii_native();
    assert_eq!(ascii.exchange(&rtu_read), None);
    // A frame with a `:` (3Ah) in it starts a line that its next bytes drop.
    assert_eq!(ascii.exchange(&[0x01, 0x03, 0x60, 0x3A, 0x00, 0x02, 0x00, 0x00]), None);
    assert_eq!(ascii.exchange(b":0103600C00028E\r\n").as_deref(), Some(&b":0103040000029264\r\n"[..]));
    let c = ascii.counters();
    assert_eq!((c.bus_messages, c.bus_errors), (1, 1));

    let mut rtu = Rig::new(Drive::factory());
    assert_eq!(rtu.drive.line_framing(), LineFraming::Rtu);
    assert_eq!(rtu.exchange(b":0103600C00028E\r\n"), None);
    assert_eq!(rtu.counters().bus_errors, 1);
    assert_eq!(rtu.exchange(&rtu_read).map(|r| r.len()), Some(9));
}

#[test]
fn the_framing_is_chosen_at_power_up() {
    assert_eq!(Drive::factory().line_framing(), LineFraming::Rtu);
    assert_eq!(Drive::boot(DriveConfig::default(), &params(0), 0).line_framing(), LineFraming::Rtu);
    // A write of 0x2192 is stored (and saved by 0x200F = 2), and acts at the next power-up.
    let mut rig = Rig::new(Drive::factory());
    let body = [0x01, 0x06, 0x21, 0x92, 0x00, 0x01];
    let mut frame = body.to_vec();
    frame.extend(crc::crc16(&body).to_le_bytes());
    assert_eq!(rig.exchange(&frame), Some(frame.clone()));
    assert_eq!(rig.drive.state().read(Obj::LineFraming), 1);
    assert_eq!(rig.drive.line_framing(), LineFraming::Rtu);
    let drive = Drive::boot(DriveConfig::default(), &rig.drive.state().params(), 0);
    assert_eq!(drive.line_framing(), LineFraming::Ascii);
    // Out of range: 03.
    let body = [0x01, 0x06, 0x21, 0x92, 0x00, 0x02];
    let mut frame = body.to_vec();
    frame.extend(crc::crc16(&body).to_le_bytes());
    assert_eq!(rig.exchange(&frame).map(|r| r[1..3].to_vec()), Some(vec![0x86, 0x03]));
}

#[test]
fn the_longest_reply_is_a_line_of_511_characters() {
    let mut rig = ascii_native();
    let reply = rig.exchange(&line(&[0x01, 0x03, 0x60, 0x00, 0x00, 125])).expect("an answer");
    assert_eq!(reply.len(), 1 + 2 * (3 + 250 + 1) + 2);
    let adu = adu_of(&reply);
    assert_eq!(&adu[..3], &[0x01, 0x03, 250]);
    // Device identification, regular access: as long as it comes.
    let reply = rig.exchange(&line(&[0x01, 0x2B, 0x0E, 0x02, 0x00])).expect("an answer");
    assert_eq!(&adu_of(&reply)[..3], &[0x01, 0x2B, 0x0E]);
}

/// The RTU reply to `body` (sent with its CRC) and the ASCII reply to its line, from two factory
/// drives.
fn both_replies(
    rtu: &mut Rig<drive_core::maps::NativeMap>,
    ascii: &mut Rig<drive_core::maps::NativeMap>,
    body: &[u8],
) -> (Option<Vec<u8>>, Option<Vec<u8>>) {
    let mut frame = body.to_vec();
    frame.extend(crc::crc16(body).to_le_bytes());
    let r = rtu.exchange(&frame).map(|r| {
        assert!(crc::frame_ok(&r));
        r[..r.len() - 2].to_vec()
    });
    let a = ascii.exchange(&line(body)).map(|l| adu_of(&l));
    (r, a)
}

/// A request to slave 0, 1 or 2: register reads and writes of the native map's pages, diagnostics,
/// device identification, and anything.
fn request() -> impl Strategy<Value = Vec<u8>> {
    let addr = prop_oneof![Just(0x6000u16), Just(0x2000), Just(0x2100), any::<u16>()];
    let pdu = prop_oneof![
        (prop_oneof![Just(3u8), Just(4)], addr.clone(), 0u16..130).prop_map(|(f, a, n)| {
            let mut p = vec![f];
            p.extend(a.to_be_bytes());
            p.extend(n.to_be_bytes());
            p
        }),
        (addr.clone(), any::<u16>()).prop_map(|(a, v)| {
            let mut p = vec![6];
            p.extend(a.to_be_bytes());
            p.extend(v.to_be_bytes());
            p
        }),
        (addr, prop::collection::vec(any::<u16>(), 1..8)).prop_map(|(a, vs)| {
            let mut p = vec![0x10];
            p.extend(a.to_be_bytes());
            p.extend((vs.len() as u16).to_be_bytes());
            p.push(2 * vs.len() as u8);
            vs.iter().for_each(|v| p.extend(v.to_be_bytes()));
            p
        }),
        (prop_oneof![Just(0u16), Just(0x0B), Just(0x0C), Just(0x0E), any::<u16>()], any::<u16>()).prop_map(|(s, d)| {
            let mut p = vec![8];
            p.extend(s.to_be_bytes());
            p.extend(d.to_be_bytes());
            p
        }),
        (1u8..5, 0u8..8).prop_map(|(c, o)| vec![0x2B, 0x0E, c, o]),
        prop::collection::vec(any::<u8>(), 1..20),
    ];
    (prop_oneof![Just(1u8), Just(1), Just(1), Just(0), Just(2)], pdu).prop_map(|(a, mut p)| {
        p.insert(0, a);
        p
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The same requests get the same answers, but for their framing; a broadcast, another
    /// drive's request and listen-only mode none; every ASCII reply is a well-formed line.
    #[test]
    fn ascii_answers_as_rtu_does(requests in prop::collection::vec(request(), 1..12)) {
        // Each request is served at the same time by both (RTU t3.5 = 4010 µs after its last
        // byte, ASCII at its LF): what a request does may depend on when (a move it started).
        let mut rtu = Rig::new(Drive::factory());
        rtu.now -= 4010;
        let mut ascii = ascii_native();
        // 0x2192 written back to RTU's 0 (in force at the next power-up): both read the same.
        ascii.drive.state_mut().write_def(Obj::LineFraming.def(), 0).unwrap();
        assert_eq!(ascii.drive.line_framing(), LineFraming::Ascii);
        for body in &requests {
            let (r, a) = both_replies(&mut rtu, &mut ascii, body);
            prop_assert_eq!(&r, &a, "{:02X?}", body);
            if body[0] != 1 {
                prop_assert_eq!(a, None);
            }
        }
        prop_assert_eq!(rtu.counters(), ascii.counters());
        prop_assert_eq!(rtu.drive.state().params(), ascii.drive.state().params());
    }
}
