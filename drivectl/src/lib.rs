//! `drivectl`: commissioning OpenStep drives over their Modbus link, in any register map.
//!
//! Every name the tool takes is a drive object's, looked up in the tables the drive itself serves
//! ([`dict`]); values are in the map's own units, as a master of that map reads them.

pub mod dict;
pub mod link;
pub mod scope;
pub mod update;

use std::collections::BTreeMap;
use std::ops::RangeInclusive;
use std::time::Duration;

use drive_core::od::Obj;
use serde::{Deserialize, Serialize};

use dict::{Dictionary, Map, Register, parse_int};
use link::{Error, Framing, LineFormat, Link, Target};

/// A register's value: a number, or a text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Value {
    /// A number, sign as the register's.
    Number(i64),
    /// ASCII text (identification strings).
    Text(String),
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Value::Number(v) => write!(f, "{v}"),
            Value::Text(s) => write!(f, "{s:?}"),
        }
    }
}

/// A drive on the link, with the registers of its map.
pub struct Drive {
    /// The connection.
    pub link: Link,
    /// The map's registers.
    pub dict: Dictionary,
    low_first: bool,
}

/// The words of `v` for `r`, in the map's order; `None` if it does not fit.
fn encode(r: &Register, v: i64, low_first: bool) -> Option<Vec<u16>> {
    match r.words {
        1 => {
            let ok = if r.signed { i16::try_from(v).is_ok() } else { u16::try_from(v).is_ok() };
            ok.then(|| vec![v as u16])
        }
        2 => {
            let ok = if r.signed { i32::try_from(v).is_ok() } else { u32::try_from(v).is_ok() };
            let (hi, lo) = ((v as u32 >> 16) as u16, v as u16);
            ok.then(|| if low_first { vec![lo, hi] } else { vec![hi, lo] })
        }
        _ => None,
    }
}

/// The value of `r` from its words.
fn decode(r: &Register, words: &[u16], low_first: bool) -> Value {
    if r.text {
        let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_be_bytes()).take_while(|b| *b != 0).collect();
        return Value::Text(String::from_utf8_lossy(&bytes).into_owned());
    }
    match (words, r.signed) {
        ([w], false) => Value::Number(i64::from(*w)),
        ([w], true) => Value::Number(i64::from(*w as i16)),
        ([a, b], signed) => {
            let (hi, lo) = if low_first { (*b, *a) } else { (*a, *b) };
            let raw = u32::from(hi) << 16 | u32::from(lo);
            Value::Number(if signed { i64::from(raw as i32) } else { i64::from(raw) })
        }
        _ => Value::Number(0),
    }
}

impl Drive {
    /// The drive behind `link`, its word order read where its map makes it a setting.
    pub async fn new(mut link: Link) -> Result<Self, Error> {
        let dict = Dictionary::of(link.map);
        let setting = match dict.of_object(Obj::MapWordOrder) {
            Some(r) if dict.map.layout().is_some() => link.read(r.at, 1).await?.first().copied().unwrap_or(0),
            _ => 0,
        };
        let low_first = dict.low_first(setting);
        Ok(Self { link, dict, low_first })
    }

    /// The register named (or at) `key`.
    pub fn register(&self, key: &str) -> Result<Register, Error> {
        self.dict.find(key).cloned().ok_or_else(|| match self.dict.reserved_at(key) {
            Some(r) => Error::Usage(format!(
                "{key} is reserved in the {} map (0x{:04X}-0x{:04X}: {}): the drive has nothing there, it reads 0 and refuses writes",
                self.dict.map.name(),
                r.first,
                r.last,
                r.about.trim_end_matches('.')
            )),
            None => Error::Usage(format!(
                "the {} map has no register {key:?} (`drivectl list` names them)",
                self.dict.map.name()
            )),
        })
    }

    /// The register of object `obj`, which a command needs.
    pub(crate) fn needs(&self, obj: Obj, what: &str) -> Result<Register, Error> {
        self.dict.of_object(obj).cloned().ok_or_else(|| {
            Error::Usage(format!(
                "the {} map has no register for {what}: switch the drive to the native map (register-map = 0, save, restart)",
                self.dict.map.name()
            ))
        })
    }

    /// Writes `v` to the register of `obj`, which `what` needs.
    pub(crate) async fn set_object(&mut self, obj: Obj, v: i64, what: &str) -> Result<(), Error> {
        let r = self.needs(obj, what)?;
        self.set(&r, v).await
    }

    /// Reads the number in the register of `obj`.
    pub(crate) async fn get_object(&mut self, obj: Obj) -> Result<i64, Error> {
        let r = self.needs(obj, "this")?;
        match self.get(&r).await? {
            Value::Number(v) => Ok(v),
            Value::Text(t) => Err(Error::Usage(format!("{} reads {t:?}, not a number", r.name))),
        }
    }

    /// Reads register `r`.
    pub async fn get(&mut self, r: &Register) -> Result<Value, Error> {
        if !r.readable {
            return Err(Error::Usage(format!("{} is write-only", r.name)));
        }
        let words = self.link.read(r.at, r.words).await?;
        Ok(decode(r, &words, self.low_first))
    }

    /// Writes `v` to register `r` (both words at once for a pair).
    pub async fn set(&mut self, r: &Register, v: i64) -> Result<(), Error> {
        if !r.writable {
            return Err(Error::Usage(format!("{} is read-only", r.name)));
        }
        let words = encode(r, v, self.low_first).ok_or_else(|| {
            Error::Usage(format!(
                "{v} does not fit {} ({} register(s), {})",
                r.name,
                r.words,
                if r.signed { "signed" } else { "unsigned" }
            ))
        })?;
        self.link.write(r.at, &words).await?;
        if r.obj == Some(Obj::MapWordOrder) {
            // The pairs after it are in the new order.
            self.low_first = self.dict.low_first(v as u16);
        }
        Ok(())
    }

    /// Writes the drive's value `v` to object `obj` (a command: a save, a motion command), at
    /// the register that holds it as the drive does ([`Dictionary::plain`]).
    async fn command(&mut self, obj: Obj, what: &str, v: i64) -> Result<(), Error> {
        let r = self.dict.plain(obj).ok_or_else(|| {
            Error::Usage(format!(
                "the {} map has no register for {what}: switch the drive to the native map (register-map = 0, save, restart)",
                self.dict.map.name()
            ))
        })?;
        self.set(&r, v).await
    }

    /// Writes `v` to object `obj`'s register, in the map's unit.
    async fn set_obj(&mut self, obj: Obj, what: &str, v: i64) -> Result<(), Error> {
        let r = self.needs(obj, what)?;
        self.set(&r, v).await
    }

    /// Reads object `obj`'s number.
    async fn get_obj(&mut self, obj: Obj, what: &str) -> Result<i64, Error> {
        let r = self.needs(obj, what)?;
        match self.get(&r).await? {
            Value::Number(v) => Ok(v),
            Value::Text(_) => Ok(0),
        }
    }

    /// Every saved setting (writable, kept once saved) and its value.
    ///
    /// The raw words of a program window (seed 004's position data groups) are read in runs
    /// of up to 125 registers, as the window serves them; every other register alone, as its
    /// map may not serve a read across entries.
    pub async fn dump(&mut self) -> Result<Settings, Error> {
        let mut values = BTreeMap::new();
        let saved: Vec<Register> = self.dict.registers.iter().filter(|r| r.saved && r.readable).cloned().collect();
        for run in runs(&saved, 125) {
            let Some(first) = run.first() else { continue };
            let words = run.iter().map(|r| r.words).sum();
            let read = self.link.read(first.at, words).await?;
            let mut at = 0;
            for r in run {
                let w = read.get(at..at + usize::from(r.words)).unwrap_or_default();
                at += usize::from(r.words);
                if let Value::Number(v) = decode(r, w, self.low_first) {
                    values.insert(r.name.clone(), v);
                }
            }
        }
        Ok(Settings { map: self.dict.map.name().to_string(), settings: values })
    }

    /// Writes every value of `settings` (for this drive's map): the microstep resolution first,
    /// which the speeds and accelerations of a map in revolutions are scaled by, then the others
    /// in the map's register order (a program window's raw words in runs of up to 123 registers).
    /// Returns how many were written; stops at the first refusal, naming it.
    pub async fn load(&mut self, settings: &Settings) -> Result<usize, Error> {
        if settings.map != self.dict.map.name() {
            return Err(Error::Usage(format!(
                "the settings are the {} map's, the drive answers with the {} map",
                settings.map,
                self.dict.map.name()
            )));
        }
        for name in settings.settings.keys() {
            let r = self.register(name)?;
            if !r.saved {
                return Err(Error::Usage(format!("{name} is not a saved setting")));
            }
        }
        let mut order: Vec<Register> =
            self.dict.registers.iter().filter(|r| settings.settings.contains_key(&r.name)).cloned().collect();
        // Stable: the map's order otherwise (seed 004 puts 0x600C after its r/min registers).
        order.sort_by_key(|r| r.obj != Some(Obj::Microsteps));
        let value = |r: &Register| settings.settings.get(&r.name).copied().unwrap_or(0);
        for run in runs(&order, 123) {
            match run {
                [] => {}
                [r] => {
                    let v = value(r);
                    self.set(r, v).await.map_err(|e| Error::Usage(format!("{} = {v}: {e}", r.name)))?;
                }
                [first, .., last] => {
                    let mut words = Vec::new();
                    for r in run {
                        let v = value(r);
                        words.extend(
                            encode(r, v, self.low_first)
                                .ok_or_else(|| Error::Usage(format!("{v} does not fit {}", r.name)))?,
                        );
                    }
                    match self.link.write(first.at, &words).await {
                        Ok(()) => {}
                        // All or nothing: nothing was written. One by one, the refusal names
                        // its register.
                        Err(Error::Refused { .. }) => {
                            for r in run {
                                let v = value(r);
                                self.set(r, v).await.map_err(|e| Error::Usage(format!("{} = {v}: {e}", r.name)))?;
                            }
                        }
                        Err(e) => return Err(Error::Usage(format!("{} to {}: {e}", first.name, last.name))),
                    }
                }
            }
        }
        Ok(order.len())
    }

    /// Saves the settings to the drive's flash (0x200F = 2) and waits for the save to end.
    pub async fn save(&mut self) -> Result<(), Error> {
        self.command(Obj::SystemControl, "system control", 2).await?;
        self.storage_done().await
    }

    /// Restores the factory settings and saves them (0x200F = 3).
    pub async fn factory_reset(&mut self) -> Result<(), Error> {
        self.command(Obj::SystemControl, "system control", 3).await?;
        self.storage_done().await
    }

    async fn storage_done(&mut self) -> Result<(), Error> {
        let Ok(r) = self.needs(Obj::StorageStatus, "storage status") else { return Ok(()) };
        for _ in 0..100 {
            if let Value::Number(s) = self.get(&r).await?
                && s & 0x08 == 0
            {
                return match s & 0x10 {
                    0 => Ok(()),
                    _ => Err(Error::Usage("the save failed (storage status bit 4)".into())),
                };
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        Err(Error::Timeout)
    }

    /// Starts a run to `target` (absolute) or by it (relative), at `speed` if given (the map's
    /// unit of the command speed).
    pub async fn move_to(&mut self, target: i64, relative: bool, speed: Option<i64>) -> Result<(), Error> {
        if let Some(s) = speed {
            self.set_obj(Obj::CommandSpeed, "the run speed", s).await?;
        }
        self.set_obj(Obj::CommandTarget, "the run target", target).await?;
        self.command(Obj::MotionCommand, "motion commands", if relative { 2 } else { 1 }).await
    }

    /// Jogs forward or backward until a stop, at `speed` if given.
    pub async fn jog(&mut self, forward: bool, speed: Option<i64>) -> Result<(), Error> {
        if let Some(s) = speed {
            self.set_obj(Obj::JogSpeed, "the jog speed", s).await?;
        }
        self.command(Obj::MotionCommand, "motion commands", if forward { 4 } else { 5 }).await
    }

    /// Stops at the deceleration, or at once (`quick`: the emergency deceleration).
    pub async fn stop(&mut self, quick: bool) -> Result<(), Error> {
        self.command(Obj::MotionCommand, "motion commands", if quick { 7 } else { 6 }).await
    }

    /// Starts the homing (method `method` if given).
    pub async fn home(&mut self, method: Option<i64>) -> Result<(), Error> {
        if let Some(m) = method {
            self.set_obj(Obj::HomingMethod, "the homing method", m).await?;
        }
        self.command(Obj::HomingControl, "homing", 1).await
    }

    /// Energises (`true`) or frees the motor.
    pub async fn enable(&mut self, on: bool) -> Result<(), Error> {
        self.command(Obj::Enable, "the motor enable", i64::from(on)).await
    }

    /// Clears the latched alarms: the motion command 13, or where the map has none (seed 004)
    /// the system control's 4.
    pub async fn clear(&mut self) -> Result<(), Error> {
        if self.dict.plain(Obj::MotionCommand).is_none() && self.dict.plain(Obj::SystemControl).is_some() {
            return self.command(Obj::SystemControl, "system control", 4).await;
        }
        self.command(Obj::MotionCommand, "motion commands", 13).await
    }

    /// Waits until the axis stands (run state 0x21AE is not 3), up to `limit`; the position.
    pub async fn wait_standing(&mut self, limit: Duration) -> Result<i64, Error> {
        let end = tokio::time::Instant::now() + limit;
        loop {
            if self.get_obj(Obj::RunState, "the run state").await? != 3 {
                return self.get_obj(Obj::Position, "the position").await;
            }
            if tokio::time::Instant::now() > end {
                return Err(Error::Timeout);
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    /// Waits for the homing to end, up to `limit`: its result (2 homed).
    pub async fn wait_homed(&mut self, limit: Duration) -> Result<i64, Error> {
        let end = tokio::time::Instant::now() + limit;
        loop {
            let r = self.get_obj(Obj::HomingResult, "the homing result").await?;
            if r != 1 {
                return Ok(r);
            }
            if tokio::time::Instant::now() > end {
                return Err(Error::Timeout);
            }
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// The status screen: each of [`STATUS`] the map has, with its value and unit (the actual
    /// position where the map has no position: seed 004).
    pub async fn status(&mut self) -> Result<Vec<(Register, Value)>, Error> {
        let mut out = Vec::new();
        let position = if self.dict.of_object(Obj::Position).is_some() { Obj::Position } else { Obj::ActualPosition };
        for obj in STATUS.map(|o| if o == Obj::Position { position } else { o }) {
            if let Some(r) = self.dict.of_object(obj).filter(|r| r.readable).cloned() {
                let v = self.get(&r).await?;
                out.push((r, v));
            }
        }
        Ok(out)
    }
}

/// `registers` in runs a request can carry: the raw words of a program window one after the
/// other, up to `most` registers; any other register alone.
fn runs(registers: &[Register], most: u16) -> Vec<&[Register]> {
    let mut out = Vec::new();
    let mut rest = registers;
    while let [first, ..] = rest {
        let mut n = 1;
        let mut words = first.words;
        while let Some(next) = rest.get(n)
            && first.obj.is_none()
            && next.obj.is_none()
            && next.at.sub.is_none()
            && next.at.register == first.at.register + words
            && words + next.words <= most
        {
            words += next.words;
            n += 1;
        }
        let (run, after) = rest.split_at(n);
        out.push(run);
        rest = after;
    }
    out
}

/// The objects the status screen shows, where the map has them.
pub const STATUS: [Obj; 16] = [
    Obj::Position,
    Obj::TargetPosition,
    Obj::RealSpeed,
    Obj::FollowingError,
    Obj::RunState,
    Obj::Enable,
    Obj::Mode,
    Obj::ErrorStatus,
    Obj::ControllerStatus,
    Obj::AlarmCode,
    Obj::HomingResult,
    Obj::SupplyVoltage,
    Obj::MotorCurrent,
    Obj::StatusWord,
    Obj::DeviceStatus,
    Obj::ErrorRegister,
];

/// A drive's saved settings, as `dump` writes them and `load` reads them (TOML).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Settings {
    /// The map the names and values are in.
    pub map: String,
    /// Each setting by name, in the map's unit.
    pub settings: BTreeMap<String, i64>,
}

impl Settings {
    /// The TOML text.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_default()
    }

    /// From TOML text.
    pub fn from_toml(text: &str) -> Result<Self, Error> {
        toml::from_str(text).map_err(|e| Error::Usage(format!("settings file: {e}")))
    }
}

/// A `NAME=VALUE` argument.
pub fn parse_assignment(s: &str) -> Result<(String, i64), Error> {
    let (name, value) = s.split_once('=').ok_or_else(|| Error::Usage(format!("{s:?}: expected NAME=VALUE")))?;
    let v = parse_int(value.trim()).ok_or_else(|| Error::Usage(format!("{value:?} is not a whole number")))?;
    Ok((name.trim().to_string(), v))
}

/// One drive found by [`scan`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Found {
    /// Its slave address.
    pub address: u8,
    /// The map it answers with (the native map for a drive that did not identify itself).
    pub map: Map,
    /// Its identification (empty for a drive that did not identify itself).
    pub identity: link::Identity,
    /// The line settings it answered at, for a scan of every setting ([`scan_every_format`]).
    pub format: Option<LineFormat>,
}

/// What a scan tells as it goes.
#[derive(Debug)]
pub enum ScanEvent<'a> {
    /// The scan goes on at these settings ([`scan_every_format`]).
    Format(LineFormat),
    /// `done` of the `total` addresses have been asked at the present settings.
    Asked {
        /// Addresses asked.
        done: usize,
        /// Addresses to ask.
        total: usize,
    },
    /// A drive answered.
    Found(&'a Found),
}

/// The margin each of a scan's waits has beyond the time on the wire: the drive's turnaround
/// (under a millisecond once its t3.5 has passed), a USB adapter's receive latency (an FTDI
/// chip's timer, 16 ms by default) and the host's scheduling.
pub const SCAN_MARGIN: Duration = Duration::from_millis(30);

/// How long a scan waits for an answer at each address, worked out from the line's settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ScanTimeouts {
    /// The probe ([`Link::probe`]) every address gets.
    pub probe: Duration,
    /// The identification an address that answered the probe gets.
    pub identify: Duration,
}

impl ScanTimeouts {
    /// The waits at `format` in `framing`: the request's time on the wire, the drive's t3.5
    /// (RTU; an ASCII line ends at its LF), the longest reply's time on the wire, the silence
    /// after which drivectl takes a reply as whole (1.5 characters, at least 3 ms), and
    /// [`SCAN_MARGIN`]. The probe is 8 bytes each way (an exception is 5); the identification
    /// request is 7 and its reply at most 256, an RTU frame's most. An ASCII line carries a
    /// frame of `n` bytes (CRC included) in `2n + 1` characters (`:`, hex, LRC, CR LF).
    pub fn of(format: LineFormat, framing: Framing) -> Self {
        let chars = |rtu_bytes: u32| match framing {
            Framing::Rtu => rtu_bytes,
            Framing::Ascii => 2 * rtu_bytes + 1,
        };
        // The Modbus serial line fixes t3.5 at 1.75 ms above 19200 baud; below, 3.5 characters
        // of 11 bits.
        let t35 = match framing {
            Framing::Ascii => Duration::ZERO,
            Framing::Rtu if format.baud > 19_200 => Duration::from_micros(1750),
            Framing::Rtu => Duration::from_micros(38_500_000 / u64::from(format.baud.max(1))),
        };
        let wait = |request: u32, reply: u32| {
            format.chars_time(chars(request))
                + t35
                + format.chars_time(chars(reply))
                + link::t15(format.baud)
                + SCAN_MARGIN
        };
        Self { probe: wait(8, 8), identify: wait(7, 256) }
    }

    /// These waits with the probe's set to `probe` (`--timeout`), the identification's no shorter.
    pub fn with_probe(self, probe: Duration) -> Self {
        Self { probe, identify: self.identify.max(probe) }
    }
}

/// Asks every address of `addresses` on `link` whether a drive is there (a probe, waiting
/// `timeouts.probe`), and identifies those that answer (waiting `timeouts.identify`): the map
/// their identification names. `report` hears of each address asked and each drive found as
/// it is found.
///
/// A probe answered by a reply that is not its own (another address', late, or spoilt) is
/// asked again once the line has been quiet for a probe's wait.
pub async fn scan(
    link: &mut Link,
    addresses: RangeInclusive<u8>,
    timeouts: ScanTimeouts,
    report: impl FnMut(ScanEvent<'_>),
) -> Result<Vec<Found>, Error> {
    scan_at(link, addresses, timeouts, None, report).await
}

/// [`scan`], each drive found said to have answered at `format`.
async fn scan_at(
    link: &mut Link,
    addresses: RangeInclusive<u8>,
    timeouts: ScanTimeouts,
    format: Option<LineFormat>,
    mut report: impl FnMut(ScanEvent<'_>),
) -> Result<Vec<Found>, Error> {
    let total = addresses.clone().count();
    let mut found = Vec::new();
    for (done, address) in addresses.enumerate() {
        link.set_slave(address);
        link.limit = timeouts.probe;
        let mut answer = link.probe().await;
        if matches!(answer, Err(Error::Link(_))) {
            tokio::time::sleep(timeouts.probe).await;
            answer = link.probe().await;
        }
        let there = match answer {
            Ok(()) | Err(Error::Refused { .. }) => true,
            Err(Error::Timeout | Error::Link(_)) => false,
            Err(e) => return Err(e),
        };
        if there {
            link.limit = timeouts.identify;
            let (map, identity) = match link.identify().await {
                Ok(identity) => (Map::from_application_name(identity.object(6)), identity),
                // It answered the probe: listed, without an identity.
                Err(Error::Refused { .. } | Error::Timeout | Error::Link(_)) => {
                    (Map::Native, link::Identity::default())
                }
                Err(e) => return Err(e),
            };
            let drive = Found { address, map, identity, format };
            report(ScanEvent::Found(&drive));
            found.push(drive);
        }
        report(ScanEvent::Asked { done: done + 1, total });
    }
    Ok(found)
}

/// [`scan`] at every setting a drive takes ([`LineFormat::every`]) on the serial port `port`,
/// waiting at each as `timeouts` has it; each drive found with the settings it answered at.
pub async fn scan_every_format(
    port: &str,
    framing: Framing,
    addresses: RangeInclusive<u8>,
    timeouts: impl Fn(LineFormat) -> ScanTimeouts,
    mut report: impl FnMut(ScanEvent<'_>),
) -> Result<Vec<Found>, Error> {
    let mut found = Vec::new();
    for format in LineFormat::every() {
        report(ScanEvent::Format(format));
        let waits = timeouts(format);
        let target = Target::Serial { port: port.to_string(), format };
        let mut link = Link::connect_raw(target, framing, waits.probe).await?;
        found.extend(scan_at(&mut link, addresses.clone(), waits, Some(format), &mut report).await?);
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;
    use link::Parity;

    fn ms(d: Duration) -> f64 {
        d.as_secs_f64() * 1000.0
    }

    #[test]
    fn scan_waits_follow_the_line() {
        let at = |baud, parity, framing| ScanTimeouts::of(LineFormat { baud, parity }, framing);
        // 9600 8N1: 8 + 8 characters of 1.042 ms, t3.5 4.01 ms, 3 ms of gathering, 30 ms.
        let slow = at(9600, Parity::None, Framing::Rtu);
        assert!((ms(slow.probe) - 53.68).abs() < 0.01, "{slow:?}");
        // 7 + 256 characters.
        assert!((ms(slow.identify) - 310.97).abs() < 0.01, "{slow:?}");
        // 115200: t3.5 fixed at 1.75 ms.
        let fast = at(115_200, Parity::None, Framing::Rtu);
        assert!((ms(fast.probe) - 36.14).abs() < 0.01, "{fast:?}");
        assert!((ms(fast.identify) - 57.58).abs() < 0.01, "{fast:?}");
        // A parity bit makes a character 11 bits.
        let even = at(9600, Parity::Even, Framing::Rtu);
        assert!((ms(even.probe) - ms(slow.probe) - 16.0 / 9.6 * 1.0).abs() < 0.01, "{even:?}");
        // ASCII: 17 characters each way for the probe, no t3.5.
        let ascii = at(9600, Parity::None, Framing::Ascii);
        assert!((ms(ascii.probe) - (2.0 * 17.0 / 0.96 + 33.0)).abs() < 0.01, "{ascii:?}");
        assert_eq!(slow.with_probe(Duration::from_millis(150)).identify, slow.identify);
        assert_eq!(slow.with_probe(Duration::from_millis(500)).identify, Duration::from_millis(500));
    }

    #[test]
    fn every_format_is_every_rate_at_every_parity() {
        let all: Vec<LineFormat> = LineFormat::every().collect();
        assert_eq!(all.len(), 21);
        assert_eq!(all.first().map(ToString::to_string).as_deref(), Some("4800 8N1"));
        assert!(all.contains(&LineFormat { baud: 38_400, parity: Parity::Even }));
        assert_eq!(all.last().map(ToString::to_string).as_deref(), Some("115200 8O1"));
    }
}
