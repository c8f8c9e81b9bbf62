//! Helpers shared by the drive-core tests: frames with CRC, a clocked exchange, state snapshots.
#![allow(dead_code, missing_docs)]

pub mod images;

use drive_core::maps::{NativeMap, RegisterMap};
use drive_core::od::OBJECTS;
use drive_core::{Drive, Instant, crc};

/// `body` followed by its CRC, low byte first.
pub fn frame(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&crc::crc16(body).to_le_bytes());
    f
}

/// A drive with a clock that the test moves.
pub struct Bus<M: RegisterMap = NativeMap> {
    pub drive: Drive<M>,
    pub now: u64,
}

impl Bus {
    pub fn factory() -> Self {
        Self::new(Drive::factory())
    }
}

impl<M: RegisterMap> Bus<M> {
    pub fn new(drive: Drive<M>) -> Self {
        Self { drive, now: 1_000_000 }
    }

    /// Sends `bytes` at the current time (all at once, as a pseudo-terminal delivers them).
    pub fn send(&mut self, bytes: &[u8]) {
        self.drive.on_rx(Instant::from_micros(self.now), bytes);
    }

    /// Lets `us` microseconds pass, firing the timer at its deadline; returns every reply sent.
    pub fn wait(&mut self, us: u64) -> Vec<Vec<u8>> {
        let end = self.now + us;
        let mut replies = Vec::new();
        while let Some(d) = self.drive.deadline() {
            if d.as_micros() > end {
                break;
            }
            self.now = self.now.max(d.as_micros());
            self.drive.on_timer(Instant::from_micros(self.now));
            replies.extend(self.drive.take_reply().map(<[u8]>::to_vec));
        }
        self.now = end;
        replies
    }

    /// Sends a frame (CRC appended) and returns the reply after the line has been quiet long enough.
    pub fn request(&mut self, body: &[u8]) -> Option<Vec<u8>> {
        self.send(&frame(body));
        let replies = self.wait(10_000);
        assert!(replies.len() <= 1, "one request, at most one reply: {replies:02X?}");
        replies.into_iter().next()
    }

    /// Every object's value and the drive's status: equal snapshots mean nothing changed.
    pub fn snapshot(&self) -> Vec<u32> {
        let st = self.drive.state();
        OBJECTS.iter().filter(|d| !d.obj.is_diagnostic()).map(|d| st.read(d.obj)).collect()
    }
}

/// The reply `body` would get: `body` with its CRC.
pub fn reply(body: &[u8]) -> Option<Vec<u8>> {
    Some(frame(body))
}

/// A drive answering through a register map, with a clock: control ticks every 50 µs, replies
/// when the line is quiet.
pub struct MapRig {
    pub drive: Drive<drive_core::maps::Maps>,
    pub now: u64,
    pub inputs: drive_core::faults::Inputs,
}

impl MapRig {
    /// A factory drive on `map`, 1 ms after power-up.
    pub fn new(map: drive_core::maps::Maps) -> Self {
        Self::with_drive(Drive::with_map(drive_core::DriveConfig::default(), map))
    }

    /// `drive`, 1 ms after power-up.
    pub fn with_drive(drive: Drive<drive_core::maps::Maps>) -> Self {
        let mut r = Self { drive, now: 0, inputs: drive_core::faults::Inputs::default() };
        r.run(1_000);
        r
    }

    /// Lets `us` pass: control ticks, and the timer at the framer's deadline; the reply, if any.
    pub fn run(&mut self, us: u64) -> Option<Vec<u8>> {
        let end = self.now + us;
        let mut reply = None;
        while self.now < end {
            self.now += 50;
            let now = Instant::from_micros(self.now);
            self.drive.tick_with(now, &self.inputs);
            self.drive.state_mut().service(now);
            if self.drive.deadline().is_some_and(|d| d.as_micros() <= self.now) {
                self.drive.on_timer(now);
                if let Some(r) = self.drive.take_reply() {
                    assert!(reply.is_none(), "two replies");
                    reply = Some(r.to_vec());
                }
            }
        }
        reply
    }

    /// Sends the whole frame `bytes` (CRC included) and returns the reply.
    pub fn exchange(&mut self, bytes: &[u8]) -> Option<Vec<u8>> {
        self.drive.on_rx(Instant::from_micros(self.now), bytes);
        self.run(10_000)
    }

    /// Sends `body` with its CRC; the reply's PDU, or the exception code.
    pub fn request(&mut self, body: &[u8]) -> Result<Vec<u8>, u8> {
        let r = self.exchange(&frame(body)).unwrap_or_else(|| panic!("no reply to {body:02X?}"));
        let pdu = r.get(1..r.len() - 2).unwrap_or_default().to_vec();
        match pdu.as_slice() {
            [f, code] if f & 0x80 != 0 => Err(*code),
            _ => Ok(pdu),
        }
    }

    /// Every object's value but the diagnostics'.
    pub fn snapshot_params(&self) -> Vec<u32> {
        let st = self.drive.state();
        OBJECTS.iter().filter(|d| !d.obj.is_diagnostic()).map(|d| st.read(d.obj)).collect()
    }

    /// Writes one register (0x06).
    pub fn write(&mut self, addr: u16, v: u16) -> Result<(), u8> {
        let [a, b] = addr.to_be_bytes();
        let [c, d] = v.to_be_bytes();
        self.request(&[1, 0x06, a, b, c, d]).map(|_| ())
    }

    /// Reads `n` registers (0x03).
    pub fn read(&mut self, addr: u16, n: u16) -> Result<Vec<u16>, u8> {
        let [a, b] = addr.to_be_bytes();
        let [c, d] = n.to_be_bytes();
        let pdu = self.request(&[1, 0x03, a, b, c, d])?;
        Ok(pdu.get(2..).unwrap_or_default().chunks(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect())
    }
}
