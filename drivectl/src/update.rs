//! `drivectl update`: a signed image sent to a drive in file records (0x15), checked by the
//! drive as it arrives, installed, and the version read back once the drive has restarted.

use std::time::{Duration, Instant};

use drive_core::od::Obj;
use drive_core::update::{FILE_REGISTERS, HEADER_LEN, Header, Phase, Reason};

use crate::dict::Address;
use crate::link::{Error, LineFormat, Link};

/// Bytes of an image in one request: 122 registers, as many as a 0x15 request carries.
pub const RECORD: usize = 244;
/// Bytes of a file of records (10 000 registers): a record does not cross into the next file.
const FILE_BYTES: usize = 2 * FILE_REGISTERS as usize;

/// A signed image, as `cargo xtask sign` writes it.
pub struct Image {
    /// Its bytes: header, program, signature.
    pub bytes: Vec<u8>,
    /// What its header says.
    pub header: Header,
}

impl Image {
    /// The image in `bytes`, if it starts with a header.
    pub fn new(bytes: Vec<u8>) -> Result<Self, Error> {
        let header = Header::parse(bytes.get(..HEADER_LEN).unwrap_or_default())
            .map_err(|r| Error::Usage(format!("not an image: {r:?} (make one with `cargo xtask sign`)")))?;
        Ok(Self { bytes, header })
    }

    /// The records it is sent in: each image offset and its bytes (an odd last byte padded
    /// with 0: registers are two bytes).
    pub fn records(&self) -> impl Iterator<Item = (u32, Vec<u8>)> + '_ {
        let mut at = 0;
        std::iter::from_fn(move || {
            let left = self.bytes.len().checked_sub(at).filter(|&n| n > 0)?;
            let n = left.min(RECORD).min(FILE_BYTES - at % FILE_BYTES);
            let mut data = self.bytes.get(at..at + n)?.to_vec();
            if data.len() % 2 == 1 {
                data.push(0);
            }
            let record = (at as u32, data);
            at += n;
            Some(record)
        })
    }
}

/// The 0x15 request of `data` from byte `offset` of an image: file `offset / 20 000 + 1`,
/// record (register) `offset / 2 % 10 000`.
pub fn record_pdu(offset: u32, data: &[u8]) -> Vec<u8> {
    let reg = offset / 2;
    let file = (reg / FILE_REGISTERS + 1) as u16;
    let record = (reg % FILE_REGISTERS) as u16;
    let mut pdu = vec![0x15, (7 + data.len()) as u8, 6];
    pdu.extend_from_slice(&file.to_be_bytes());
    pdu.extend_from_slice(&record.to_be_bytes());
    pdu.extend_from_slice(&((data.len() / 2) as u16).to_be_bytes());
    pdu.extend_from_slice(data);
    pdu
}

/// The shortest time `image` can take on a line of `format`: each record's request and its
/// echo (address, function, byte count, 7 bytes of head, the data, CRC) at the line's bits a
/// character, and t3.5 after each (3.5 characters; 1.75 ms above 19 200 baud, as the Modbus
/// serial line has it).
pub fn wire_limit(image: &Image, format: LineFormat) -> Duration {
    let t35 = if format.baud > 19_200 { Duration::from_micros(1750) } else { format.chars_time(4) };
    image.records().map(|(_, data)| 2 * format.chars_time(data.len() as u32 + 12) + 2 * t35).sum()
}

/// `major.minor.patch` of a version as the header packs it.
pub fn version(v: u32) -> String {
    format!("{}.{}.{}", v >> 16, (v >> 8) & 0xFF, v & 0xFF)
}

/// What 0x2251 says, in words.
pub fn reason(code: u16) -> &'static str {
    match code {
        c if c == Reason::NotAnImage as u16 => "not an image",
        c if c == Reason::Board as u16 => "the image is for another board",
        c if c == Reason::Length as u16 => "fewer bytes than the image's header says (truncated)",
        c if c == Reason::Signature as u16 => {
            "its signature: unsigned, signed with another key than the drive's, or changed since it was signed"
        }
        c if c == Reason::Store as u16 => "the image needs a newer parameter store than the drive's",
        c if c == Reason::TooLarge as u16 => "the program is longer than the drive's slot",
        c if c == Reason::Flash as u16 => "the drive's flash did not take it",
        _ => "no reason given",
    }
}

/// What 0x2261 says, in words.
pub fn boot_state(code: u16) -> &'static str {
    match code {
        0 => "confirmed",
        1 => "on trial: it has not confirmed itself, and the next reset goes back",
        2 => "rolled back",
        3 => "an update is marked for the next reset",
        _ => "in an unknown state",
    }
}

/// A drive's transfer as 0x2250-0x2255 say.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Status {
    /// 0x2250 (`update::Phase`).
    pub phase: u16,
    /// 0x2251 (`update::Reason`).
    pub reason: u16,
    /// Bytes taken.
    pub received: u32,
}

/// An update of one drive on a link whose requests it frames itself ([`Link::connect_raw`]),
/// talking to the drive's native objects in its map (a sub-indexed map's window).
pub struct Updater<'a> {
    /// The link, at the drive's address.
    pub link: &'a mut Link,
}

impl Updater<'_> {
    fn at(&self, obj: Obj) -> Address {
        let sub = if self.link.map.sub_indexed() { Some(0xFF) } else { None };
        Address { register: obj.def().addr, sub }
    }

    async fn read32(&mut self, obj: Obj) -> Result<u32, Error> {
        let at = self.at(obj);
        let w = self.link.read(at, 2).await?;
        Ok(u32::from(w.first().copied().unwrap_or(0)) << 16 | u32::from(w.get(1).copied().unwrap_or(0)))
    }

    async fn read16(&mut self, obj: Obj) -> Result<u16, Error> {
        let at = self.at(obj);
        Ok(self.link.read(at, 1).await?.first().copied().unwrap_or(0))
    }

    /// The running image's version (0x2259).
    pub async fn running(&mut self) -> Result<u32, Error> {
        self.read32(Obj::FirmwareVersion).await
    }

    /// What the drive's boot loader state says of the image it runs (0x2261, `update::BootState`).
    pub async fn boot_state(&mut self) -> Result<u16, Error> {
        self.read16(Obj::FirmwareState).await
    }

    /// The transfer's state.
    pub async fn status(&mut self) -> Result<Status, Error> {
        Ok(Status {
            phase: self.read16(Obj::UpdateState).await?,
            reason: self.read16(Obj::UpdateReason).await?,
            received: self.read32(Obj::UpdateReceived).await?,
        })
    }

    /// Why the drive would not take an image at all: its writes locked, or no slots.
    pub async fn check(&mut self) -> Result<(), Error> {
        if self.read16(Obj::WriteLock).await? == 1 {
            return Err(Error::Usage(
                "its writes are locked (0x225C): unlock it first, `drivectl set unlock=PASSWORD`".into(),
            ));
        }
        if self.read16(Obj::FirmwareKey).await? == 2 {
            return Err(Error::Usage("it takes no firmware images (0x225B = 2)".into()));
        }
        Ok(())
    }

    /// Sends `image`, record by record, telling `progress` the bytes taken; then checks that the
    /// drive holds it whole and checked. A refusal names the drive's reason.
    pub async fn send(&mut self, image: &Image, mut progress: impl FnMut(u32)) -> Result<(), Error> {
        for (offset, data) in image.records() {
            let pdu = record_pdu(offset, &data);
            // A lost reply is asked again: the drive takes the same record twice once.
            let mut sent = self.link.exchange(&pdu).await;
            if matches!(sent, Err(Error::Timeout | Error::Link(_))) {
                sent = self.link.exchange(&pdu).await;
            }
            if let Err(e) = sent {
                return Err(self.why(e).await);
            }
            progress(offset + data.len() as u32);
        }
        Ok(())
    }

    /// Whether the drive holds the image whole and checked, ready to install; why not if not.
    pub async fn ready(&mut self) -> Result<(), Error> {
        let s = self.status().await?;
        match s.phase {
            p if p == Phase::Ready as u16 => Ok(()),
            p if p == Phase::Receiving as u16 => {
                Err(Error::Usage(format!("the drive holds {} bytes of the image, not all of it", s.received)))
            }
            _ => Err(Error::Usage(format!("the drive holds no checked image: {}", reason(s.reason)))),
        }
    }

    /// `e`, with the drive's reason where it gives one.
    async fn why(&mut self, e: Error) -> Error {
        match (e, self.status().await) {
            (Error::Refused { code, .. }, Ok(s)) if s.phase == Phase::Failed as u16 => {
                Error::Usage(format!("refused (exception {code:02X}): {}", reason(s.reason)))
            }
            (e, _) => e,
        }
    }

    /// Installs the image the drive holds: it checks it once more, marks it for its boot loader
    /// and restarts. Refused, with the reason, if the image is not whole and checked.
    pub async fn install(&mut self) -> Result<(), Error> {
        let at = self.at(Obj::UpdateControl);
        match self.link.write(at, &[2]).await {
            Ok(()) => Ok(()),
            Err(e) => Err(self.why(e).await),
        }
    }

    /// The version the drive reports after its restart: `expected` as soon as it does, else
    /// what it last reported once `limit` has passed (a drive answers until it restarts, and not
    /// while its boot loader copies the image).
    pub async fn restarted(&mut self, expected: u32, limit: Duration) -> Result<u32, Error> {
        let end = Instant::now() + limit;
        let mut last = Err(Error::Timeout);
        while Instant::now() < end {
            match self.running().await {
                Ok(v) if v == expected => return Ok(v),
                Ok(v) => last = Ok(v),
                Err(e @ (Error::Timeout | Error::Link(_))) => last = Err(e),
                Err(e) => return Err(e),
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        last
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::Parity;

    #[test]
    fn records_stay_in_their_files_and_cover_the_image() {
        let header = Header { board: drive_core::update::Board::Simulator, version: 1, length: 41_000, store: 1 };
        let mut bytes = header.to_bytes().to_vec();
        bytes.resize(HEADER_LEN + 41_000 + 64, 0xAB);
        let image = Image::new(bytes).expect("image");
        let records: Vec<_> = image.records().collect();
        let mut at = 0;
        for (offset, data) in &records {
            assert_eq!(*offset, at);
            assert!(data.len() <= RECORD);
            assert_eq!(offset / 20_000, (offset + data.len() as u32 - 1) / 20_000, "within one file");
            at += data.len() as u32;
        }
        assert_eq!(at as usize, image.bytes.len());
        assert_eq!(&record_pdu(20_000, &[1, 2])[..9], &[0x15, 9, 6, 0, 2, 0, 0, 0, 1]);
        // 115 200 8N1: a full record is 2 × 256 characters of 86.8 µs and 2 × 1.75 ms.
        let limit = wire_limit(&image, LineFormat { baud: 115_200, parity: Parity::None });
        let full = 2.0 * 256.0 * 10.0 / 115_200.0 + 3.5e-3;
        assert!((limit.as_secs_f64() / records.len() as f64 - full).abs() < 2e-3, "{limit:?}");
    }
}
