//! The PVT run at each tick: the next segment when the running one ends, taken from the table
//! (modes 1 and 2) or the FIFO (mode 3) that the bus side fills (see the `pvt` module).

use super::{Controller, Settings};
use crate::motion::cubic::{Ahead, Cubic, Point, TABLE_SIZE, Table};
use crate::units::{Instant, TICK_MICROS};

/// Controller status bit 5: the mode 3 FIFO is empty.
pub const STATUS_FIFO_EMPTY: u8 = 1 << 5;
/// Controller status bit 6: the mode 3 FIFO holds fewer points than the low mark 0x6025.
pub const STATUS_FIFO_LOW: u8 = 1 << 6;
/// Controller status bit 7: the mode 3 FIFO holds more points than the high mark 0x6026.
pub const STATUS_FIFO_HIGH: u8 = 1 << 7;
/// 0x2111 bit 0: the FIFO ran dry while the axis was moving.
pub const FAULT_UNDERFLOW: u8 = 1;

/// Segments started in one tick at most. Only a few of no time can follow each other (see
/// the `pvt` module); the bound keeps a tick's work bounded whatever the table holds.
const SEGMENTS_PER_TICK: usize = 16;

/// One phase of a table run: indices `first..=last`, `times` times.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Phase {
    pub(crate) first: u16,
    pub(crate) last: u16,
    pub(crate) times: u16,
}

/// Where the points of a run come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Source {
    /// Modes 1 and 2: phases of the table; `phase` is the current one, `next` its next index,
    /// `left` how many more times it runs, this one included.
    Table { phases: [Phase; 3], phase: usize, next: u16, left: u16 },
    /// Mode 3: the ring.
    Fifo,
}

/// A PVT run in progress.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Run {
    pub(crate) source: Source,
    /// The point the running segment heads to.
    pub(crate) to: Point,
}

/// The PVT points: which slots of the table hold points (the bus side pushes, a FIFO run takes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Pvt {
    /// First stored point (mode 3's ring; 0 in modes 1 and 2).
    pub(crate) head: u16,
    /// Points stored (modes 1, 2) or queued (mode 3).
    pub(crate) len: u16,
    /// The last point pushed: the next one's segment starts there.
    pub(crate) last: Option<Point>,
    /// 0x2111.
    pub(crate) fault: u8,
}

impl Pvt {
    /// Points stored or queued (0x2110).
    pub(crate) fn count(&self) -> u16 {
        self.len
    }

    /// The next point of `source`, and its index; a FIFO point leaves the queue.
    pub(crate) fn next_point(&mut self, source: &mut Source, table: &Table) -> Option<(u16, Point)> {
        let index = match source {
            Source::Fifo => {
                if self.len == 0 {
                    return None;
                }
                let i = self.head;
                self.head = ((usize::from(i) + 1) % TABLE_SIZE) as u16;
                self.len -= 1;
                i
            }
            Source::Table { .. } => source.next_index()?,
        };
        table.get(usize::from(index)).map(|p| (index, p))
    }

    /// The point [`Pvt::next_point`] would give next, without taking it.
    fn peek_point(&self, source: &Source, table: &Table) -> Option<Point> {
        let index = match *source {
            Source::Fifo if self.len == 0 => return None,
            Source::Fifo => self.head,
            mut s => s.next_index()?,
        };
        table.get(usize::from(index))
    }
}

impl Phase {
    pub(crate) fn new(first: u32, last: u32, times: u32) -> Self {
        Self { first: first as u16, last: last as u16, times: times as u16 }
    }
}

impl Source {
    pub(crate) fn table(phases: [Phase; 3]) -> Self {
        let mut s = Source::Table { phases, phase: 0, next: 0, left: 0 };
        s.enter(0);
        s
    }

    /// The next table index of the run, if any is left.
    fn next_index(&mut self) -> Option<u16> {
        loop {
            let Source::Table { phases, phase, next, left } = self else { return None };
            let ph = phases.get(*phase).copied()?;
            if *left == 0 {
                let k = *phase + 1;
                self.enter(k);
            } else if *next <= ph.last {
                *next += 1;
                return Some(*next - 1);
            } else {
                *left -= 1;
                *next = ph.first;
            }
        }
    }

    fn enter(&mut self, k: usize) {
        if let Source::Table { phases, phase, next, left } = self {
            *phase = k;
            let p = phases.get(k).copied().unwrap_or_default();
            (*next, *left) = (p.first, p.times);
        }
    }
}

impl Controller {
    /// Starts the PVT run `source` on the next control tick after `now`: its first segment from
    /// where the axis stands to its first point (from `pvt` and `table`), built here. A first
    /// point of no time is where the axis stands: the run starts with the segment after it, so
    /// that the tick that starts the run builds nothing. Nothing happens if `source` is empty.
    pub(crate) fn start_run(&mut self, now: Instant, mut source: Source, pvt: &mut Pvt, table: &Table) {
        let Some((mut index, mut to)) = pvt.next_point(&mut source, table) else { return };
        let mut cubic = Cubic::new(self.axis.setpoint().whole, 0, to);
        for _ in 0..SEGMENTS_PER_TICK {
            if cubic.ticks() > 0 {
                break;
            }
            let Some((i, p)) = pvt.next_point(&mut source, table) else { break };
            cubic = Cubic::new(cubic.p1(), to.velocity, p);
            (index, to) = (i, p);
        }
        let at = self.axis.next_tick(now);
        self.axis.follow(at, cubic, &mut None);
        self.run = Some(Run { source, to });
        self.status.pvt_pointer = index;
    }

    /// The PVT part of a control tick at `now`: the next segment whenever the running one has
    /// ended (starting exactly at its end, so time does not drift either).
    pub(crate) fn pvt_tick(&mut self, s: &Settings, now: Instant, pvt: &mut Pvt, table: &Table) {
        let Some(mut run) = self.run else { return };
        let Some((mut start, mut cubic)) = self.axis.cubic() else {
            // Stopped by something else (0x6053, disable).
            self.run = None;
            return;
        };
        let mut started = false;
        for _ in 0..SEGMENTS_PER_TICK {
            let length = cubic.ticks() * TICK_MICROS;
            if now.since(start) < length || now < start {
                break;
            }
            let end = start.plus_micros(length);
            match pvt.next_point(&mut run.source, table) {
                Some((i, p)) => {
                    cubic = Cubic::new(cubic.p1(), run.to.velocity, p);
                    start = end;
                    self.axis.follow(start, cubic, &mut self.ahead);
                    run.to = p;
                    self.status.pvt_pointer = i;
                    started = true;
                }
                None => {
                    self.run = None;
                    if run.to.velocity == 0 {
                        self.axis.stand_on_cubic_end();
                    } else {
                        pvt.fault |= FAULT_UNDERFLOW;
                        self.decelerate_to_stop(s);
                    }
                    return;
                }
            }
        }
        // The next segment, if its point is there already, is built a piece a tick before it
        // starts (its first tick would otherwise build it all: three times a tick's work), from
        // the tick after this one starts (a tick that starts a segment has done its share). Once
        // built from this segment's end, nothing is left to do until it starts (`follow` checks
        // that it is the segment that starts).
        let built = self.ahead.is_some_and(|a| a.is_built() && a.cubic.p0 == cubic.p1());
        if !started
            && !built
            && let Some(p) = pvt.peek_point(&run.source, table)
        {
            let next = Cubic::new(cubic.p1(), run.to.velocity, p);
            match &mut self.ahead {
                Some(a) if a.cubic == next => {
                    a.advance();
                }
                ahead => *ahead = Some(Ahead::new(next)),
            }
        }
        self.run = Some(run);
    }
}
