//! The drive's scope and black box from the host: configure and arm the scope, wait for its
//! capture, read a capture out whole (its sequence number the same, done, before and after
//! the rows), write it as CSV and draw it with the simulator's plotting module.

use std::path::Path;
use std::time::{Duration, Instant};

use drive_core::od::Obj;
use drive_core::scope::{MAX_SIGNALS, Phase, Signal, Trigger};
use hal_sim::plot::{COLOURS, Panel, plot_panels};

use crate::Drive;
use crate::dict::{Address, Map};
use crate::link::Error;

/// The control tick's period on the board, s: a row every `divider` of them.
pub const TICK_S: f64 = 50e-6;

/// A signal by its name on the command line (`commanded-position`) or its code.
pub fn signal(name: &str) -> Result<Signal, Error> {
    let key = name.trim().to_ascii_lowercase();
    Signal::ALL
        .into_iter()
        .find(|s| key == kebab(s.name()) || key.parse::<u16>().is_ok_and(|c| c == *s as u16))
        .ok_or_else(|| {
            let names: Vec<String> = Signal::ALL.iter().map(|s| kebab(s.name())).collect();
            Error::Usage(format!("no signal {name:?}: {}", names.join(", ")))
        })
}

/// A signal's name on the command line and in CSV headers.
pub fn kebab(name: &str) -> String {
    name.replace(' ', "-").to_ascii_lowercase()
}

/// A trigger as the command line says it: `now`, `move`, `alarm`,
/// `rising|falling|crossing:SIGNAL:LEVEL`, `set|cleared:SIGNAL:MASK`.
pub fn trigger(spec: &str) -> Result<Trigger, Error> {
    let parts: Vec<&str> = spec.split(':').collect();
    let number = |s: &str| crate::dict::parse_int(s).ok_or_else(|| Error::Usage(format!("{s} is not a number")));
    let level = |s: &str| -> Result<i32, Error> {
        let v = number(s)?;
        i32::try_from(v)
            .or_else(|_| u32::try_from(v).map(|m| m as i32))
            .map_err(|_| Error::Usage(format!("{s} does not fit 32 bits")))
    };
    let code = match parts.first().copied() {
        Some("now") => 0,
        Some("move") => 1,
        Some("rising") => 2,
        Some("falling") => 3,
        Some("crossing") => 4,
        Some("set") => 5,
        Some("cleared") => 6,
        Some("alarm") => 7,
        _ => 99,
    };
    let t = match (code, parts.as_slice()) {
        (0 | 1 | 7, [_]) => Trigger::from_code(code, Signal::None, 0),
        (2..=6, [_, s, l]) => Trigger::from_code(code, signal(s)?, level(l)?),
        _ => None,
    };
    t.ok_or_else(|| {
        Error::Usage(format!(
            "no trigger {spec:?}: now, move, alarm, rising|falling|crossing:SIGNAL:LEVEL or set|cleared:SIGNAL:MASK"
        ))
    })
}

/// What the scope records and when: the objects 0x2220-0x222E.
#[derive(Clone, Debug, PartialEq)]
pub struct Setup {
    /// Up to 8 signals.
    pub signals: Vec<Signal>,
    /// A row every this many ticks.
    pub divider: u16,
    /// What triggers the capture.
    pub trigger: Trigger,
    /// The share before the trigger, percent.
    pub pre_percent: u8,
    /// Repeated: armed again by the drive once a capture is read (0x222E = 1).
    pub repeat: bool,
}

impl Setup {
    /// The rows a capture holds.
    fn rows(&self) -> usize {
        let mut config = drive_core::scope::Config::OFF;
        for (slot, s) in config.signals.iter_mut().zip(&self.signals) {
            *slot = *s;
        }
        drive_core::scope::WORDS / usize::from(config.row_words().max(1))
    }

    /// The time the scope takes to record the share before the trigger, s (on the board).
    pub fn pre_trigger_s(&self) -> f64 {
        (self.rows() * usize::from(self.pre_percent) / 100) as f64 * f64::from(self.divider) * TICK_S
    }

    /// The time a whole capture takes, s (on the board).
    pub fn capture_s(&self) -> f64 {
        self.rows() as f64 * f64::from(self.divider) * TICK_S
    }
}

/// What the drive says of the capture it holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Head {
    sequence: u16,
    rows: usize,
    width: usize,
    trigger_row: usize,
    period_us: u32,
}

/// A capture read out whole.
#[derive(Clone, Debug, PartialEq)]
pub struct Capture {
    /// Its signals, in a row's order.
    pub signals: Vec<Signal>,
    /// The time between rows, s.
    pub period_s: f64,
    /// The row of the trigger.
    pub trigger_row: usize,
    /// Its number (captures finished since power-up).
    pub sequence: u16,
    /// The rows: each signal's value.
    pub rows: Vec<Vec<i64>>,
}

impl Capture {
    /// Row `k`'s time from the trigger, s.
    pub fn time(&self, k: usize) -> f64 {
        (k as f64 - self.trigger_row as f64) * self.period_s
    }

    /// The capture as CSV: `time_s` and a column a signal (their units in docs/registers.md).
    pub fn to_csv(&self) -> String {
        let mut out = String::from("time_s");
        for s in &self.signals {
            out.push(',');
            out.push_str(&kebab(s.name()));
        }
        out.push('\n');
        for (k, row) in self.rows.iter().enumerate() {
            out.push_str(&format!("{:.6}", self.time(k)));
            for v in row {
                out.push_str(&format!(",{v}"));
            }
            out.push('\n');
        }
        out
    }

    /// Draws it to `png`: a panel a unit, the trigger at time 0.
    pub fn plot(&self, png: &Path, title: &str) -> Result<(), Error> {
        let mut units: Vec<&str> = Vec::new();
        for s in &self.signals {
            if !units.contains(&s.unit()) {
                units.push(s.unit());
            }
        }
        let names: Vec<String> = self.signals.iter().map(|s| s.name().to_string()).collect();
        let panels: Vec<Panel<'_>> = units
            .iter()
            .map(|&unit| {
                let series = self
                    .signals
                    .iter()
                    .enumerate()
                    .filter(|(_, s)| s.unit() == unit)
                    .enumerate()
                    .map(|(n, (i, _))| {
                        let points = self.rows.iter().enumerate().map(|(k, r)| (self.time(k), r[i] as f64)).collect();
                        (names[i].as_str(), COLOURS[n % COLOURS.len()], if n == 0 { 2 } else { 1 }, points)
                    })
                    .collect();
                let title = self.signals.iter().filter(|s| s.unit() == unit).map(|s| s.name()).collect::<Vec<_>>();
                Panel { title: title.join(", "), y_desc: unit, series }
            })
            .collect();
        plot_panels(&panels, png, title).map_err(|e| Error::Usage(e.to_string()))
    }
}

/// Where a capture's window starts in `map` (the native map's registers in every map: seed
/// 003's through its window, sub-index 0xFF), and the most registers a request reads there.
fn window(map: Map, black_box: bool) -> (Address, usize) {
    use drive_core::state::recording::{BLACK_BOX_WINDOW, SCOPE_WINDOW};
    let register = if black_box { BLACK_BOX_WINDOW } else { SCOPE_WINDOW };
    match map {
        Map::Ec57 => (Address { register, sub: Some(drive_core::maps::ec57::WINDOW_SUB) }, 16),
        _ => (Address { register, sub: None }, 125),
    }
}

impl Drive {
    /// Writes `setup` and arms the scope.
    pub async fn scope_arm(&mut self, setup: &Setup) -> Result<(), Error> {
        if setup.signals.is_empty() || setup.signals.len() > MAX_SIGNALS {
            return Err(Error::Usage(format!("1 to {MAX_SIGNALS} signals")));
        }
        for (k, obj) in drive_core::state::recording::SIGNALS.into_iter().enumerate() {
            let code = setup.signals.get(k).map_or(0, |s| *s as i64);
            self.set_object(obj, code, "the scope").await?;
        }
        let (kind, watched, level) = setup.trigger.code();
        self.set_object(Obj::ScopeDivider, i64::from(setup.divider), "the scope").await?;
        self.set_object(Obj::ScopeTrigger, i64::from(kind), "the scope").await?;
        self.set_object(Obj::ScopeTriggerSignal, watched as i64, "the scope").await?;
        self.set_object(Obj::ScopeTriggerLevel, i64::from(level), "the scope").await?;
        self.set_object(Obj::ScopePreTrigger, i64::from(setup.pre_percent), "the scope").await?;
        self.set_object(Obj::ScopeMode, i64::from(setup.repeat), "the scope").await?;
        self.set_object(Obj::ScopeControl, 1, "the scope").await
    }

    /// Waits for the scope's capture (up to `limit`), telling `progress` where it is.
    pub async fn scope_wait(&mut self, limit: Duration, mut progress: impl FnMut(Phase)) -> Result<(), Error> {
        let start = Instant::now();
        loop {
            let phase = self.scope_phase().await?;
            progress(phase);
            match phase {
                Phase::Done => return Ok(()),
                Phase::Idle => return Err(Error::Usage("the scope is idle: nothing armed it".into())),
                Phase::Armed | Phase::Triggered if start.elapsed() > limit => {
                    return Err(Error::Usage(format!(
                        "the scope did not {} within {:.0} s",
                        if phase == Phase::Armed { "trigger" } else { "finish" },
                        limit.as_secs_f64()
                    )));
                }
                _ => tokio::time::sleep(Duration::from_millis(50)).await,
            }
        }
    }

    async fn scope_phase(&mut self) -> Result<Phase, Error> {
        let state = self.get_object(Obj::ScopeState).await?;
        Ok(match state {
            1 => Phase::Armed,
            2 => Phase::Triggered,
            3 => Phase::Done,
            _ => Phase::Idle,
        })
    }

    /// Reads the capture held (the black box's with `black_box`) whole, or with `rows` that
    /// many of its rows, the trigger's as far into them as into the capture: read again while
    /// a capture changes under the read, at most three times. `progress` is told the
    /// registers read and their count.
    pub async fn capture(
        &mut self,
        black_box: bool,
        rows: Option<usize>,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Capture, Error> {
        let (at, most) = window(self.dict.map, black_box);
        for _ in 0..3 {
            let head = self.capture_head(black_box).await?;
            let len = rows.map_or(head.rows, |n| n.clamp(1, head.rows.max(1)));
            // The first row read: the trigger as far into the rows read as into the capture.
            let first = head.trigger_row * (head.rows - len) / head.rows.max(1);
            let (skip, n) = (first * head.width, len * head.width);
            let mut words = Vec::with_capacity(n);
            while words.len() < n {
                let k = words.len();
                let q = (n - k).min(most);
                let register = at.register + (skip + k) as u16;
                words.extend(self.link.read(Address { register, ..at }, q as u16).await?);
                progress(words.len(), n);
            }
            if self.capture_head(black_box).await? != head {
                continue;
            }
            let signals = self.capture_signals(black_box).await?;
            // The drive's own measure of its rows' spacing; the divider's ticks if it has none
            // (a capture that ended at its trigger).
            let period_s = match head.period_us {
                0 => TICK_S * f64::from(self.capture_divider(black_box).await?),
                us => f64::from(us) * 1e-6,
            };
            let rows = words.chunks(head.width.max(1)).map(|row| decode_row(&signals, row)).collect();
            let read = if black_box { Obj::BlackBoxRead } else { Obj::ScopeRead };
            self.set_object(read, i64::from(head.sequence), "the scope").await?;
            return Ok(Capture {
                signals,
                period_s,
                trigger_row: head.trigger_row - first,
                sequence: head.sequence,
                rows,
            });
        }
        Err(Error::Usage("the capture changed three times while it was read: stop the scope first".into()))
    }

    /// The capture held, its registers read in one request (0x2230-0x2237, 0x2238-0x2240); an
    /// error if none is held.
    async fn capture_head(&mut self, black_box: bool) -> Result<Head, Error> {
        let [state, sequence, rows, trigger, period] = if black_box {
            [
                Obj::BlackBoxState,
                Obj::BlackBoxSequence,
                Obj::BlackBoxRows,
                Obj::BlackBoxTriggerRow,
                Obj::BlackBoxRowPeriod,
            ]
        } else {
            [Obj::ScopeState, Obj::ScopeSequence, Obj::ScopeRows, Obj::ScopeTriggerRow, Obj::ScopeRowPeriod]
        };
        // From the state to the row period's last register, as the objects lie.
        let first = self.needs(state, "the scope")?;
        let w = self.link.read(first.at, (period.def().end() - u32::from(state.def().addr)) as u16).await?;
        let at = |obj: Obj, k: u16| {
            usize::from(w.get(usize::from(obj.def().addr - state.def().addr + k)).copied().unwrap_or(0))
        };
        let word = |obj: Obj| at(obj, 0);
        if word(state) != Phase::Done as usize {
            let what = if black_box { "black box" } else { "scope" };
            return Err(Error::Usage(format!("the {what} holds no capture")));
        }
        // High word first, as the native map has it in every map.
        let period_us = ((at(period, 0) as u32) << 16) | at(period, 1) as u32;
        let width =
            if black_box { usize::from(drive_core::scope::BLACK_BOX.row_words()) } else { word(Obj::ScopeRowWords) };
        Ok(Head { sequence: word(sequence) as u16, rows: word(rows), width, trigger_row: word(trigger), period_us })
    }

    async fn capture_signals(&mut self, black_box: bool) -> Result<Vec<Signal>, Error> {
        if black_box {
            return Ok(drive_core::scope::BLACK_BOX.signals.into_iter().filter(|s| *s != Signal::None).collect());
        }
        let mut signals = Vec::new();
        for obj in drive_core::state::recording::SIGNALS {
            let code = self.get_object(obj).await?;
            if let Some(s) = Signal::from_code(code as u16).filter(|s| *s != Signal::None) {
                signals.push(s);
            }
        }
        Ok(signals)
    }

    async fn capture_divider(&mut self, black_box: bool) -> Result<u16, Error> {
        if black_box {
            Ok(drive_core::scope::BLACK_BOX.divider)
        } else {
            Ok(self.get_object(Obj::ScopeDivider).await? as u16)
        }
    }
}

/// A row's words as the signals' values.
fn decode_row(signals: &[Signal], words: &[u16]) -> Vec<i64> {
    let mut out = Vec::with_capacity(signals.len());
    let mut k = 0;
    for s in signals {
        let w = |i: usize| words.get(i).copied().unwrap_or(0);
        out.push(match (s.words(), s.signed()) {
            (2, _) => i64::from(((u32::from(w(k)) << 16) | u32::from(w(k + 1))) as i32),
            (_, true) => i64::from(w(k) as i16),
            _ => i64::from(w(k)),
        });
        k += usize::from(s.words());
    }
    out
}
