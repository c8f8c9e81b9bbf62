//! The handoff between two owners of the controller: the control tick, which owns the one that
//! runs, and the bus side, which keeps a model of it inside the drive's state (what requests
//! read, and what they plan on).
//!
//! Neither waits for the other. The bus side lends its model to the tick ([`Lent`]) and leaves
//! it alone until the tick has synced it ([`Controller::sync`], at the start of a tick; no
//! planning: `cargo xtask tick-cost` measures such a tick, a plan taken over and the tick's own
//! work included). A sync first takes in what the bus side ordered since the last one
//! ([`Orders`]) and a plan it made (its axis' version moved from what it learned then:
//! [`Base`]), then tells the model what the tick did since:
//!
//! - the settings are the bus side's: the tick takes them whole when they changed
//!   ([`Orders`]);
//! - the axis: a plan the bus side made (its
//!   [`Axis::version`](crate::motion::axis::Axis::version) moved) replaces the tick's axis
//!   at the plan's first tick (the sync waits for it), if the tick has not changed course on its
//!   own since (a fault, a stop, the watchdog: then the plan is dropped, the tick's stop wins);
//!   the bus side plans from the axis extrapolated to that tick, so the handover is seamless
//!   (the plan's track is copied as far as it is used, and the model learns only the tick's
//!   last setpoint back). Otherwise the model takes the tick's walk;
//! - status bits are the tick's: the bus side orders the ones it cleared cleared, and the
//!   output pins' levels the master wrote written ([`Orders`]);
//! - a PVT run the bus side started or ended, the PVT points it pushed or cleared, a stop, a
//!   homing's watch and suspended stops, the fault history emptied ([`Orders`]), and a frame
//!   heard (the watchdog restarts);
//! - the events the tick raised go up, for the bus side to act on.

use super::run::{Pvt, Run};
use super::{Controller, Events, Outputs, Settings, Shared, Status, Watch};
use crate::faults::Inputs;
use crate::scope::Config;
use crate::units::{Instant, TICK_MICROS};

/// What the bus side learned of the tick's controller at the last sync: the version of its
/// axis, which a plan the bus side made moves on (and so is told apart by).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Base {
    pub(crate) version: u32,
}

/// Status bits the bus side cleared (a master's write-1-to-clear, an alarm clear, a homing's
/// fresh start, input edges it carried out): masks of [`Status`]'s fields and of 0x2111.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Clears {
    pub(crate) error: u8,
    pub(crate) controller: u8,
    pub(crate) notify: u8,
    pub(crate) faults: u8,
    pub(crate) comm: u8,
    pub(crate) probes: u8,
    pub(crate) input_edges: u8,
    pub(crate) pvt_fault: u8,
}

impl Clears {
    /// Clears nothing.
    pub(crate) const NONE: Self =
        Self { error: 0, controller: 0, notify: 0, faults: 0, comm: 0, probes: 0, input_edges: 0, pvt_fault: 0 };

    /// Both sets of bits.
    pub(crate) fn or(self, o: Self) -> Self {
        Self {
            error: self.error | o.error,
            controller: self.controller | o.controller,
            notify: self.notify | o.notify,
            faults: self.faults | o.faults,
            comm: self.comm | o.comm,
            probes: self.probes | o.probes,
            input_edges: self.input_edges | o.input_edges,
            pvt_fault: self.pvt_fault | o.pvt_fault,
        }
    }

    /// Clears the bits in `s` and `pvt`.
    pub(crate) fn clear(&self, s: &mut Status, pvt: &mut Pvt) {
        s.error &= !self.error;
        s.controller &= !self.controller;
        s.notify &= !self.notify;
        s.faults &= !self.faults;
        s.comm &= !self.comm;
        s.probes &= !self.probes;
        s.input_edges &= !self.input_edges;
        pvt.fault &= !self.pvt_fault;
    }
}

/// What the bus side orders the tick to do on its own state since the last sync: a stop ramp
/// from wherever the axis is when the order arrives (a PVT stop), status bits to clear, the
/// output pins' levels the master wrote, new settings to take, a PVT run started or ended, the
/// PVT queue as the bus side left it and the points it pushed since, a homing's watch and
/// suspended stops, the fault history emptied.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Orders {
    /// Stop: a ramp at the stop deceleration, and the PVT run ends.
    pub(crate) stop: bool,
    /// The settings changed.
    pub(crate) settings: bool,
    /// Status bits to clear.
    pub(crate) clear: Clears,
    /// The output pins' levels the master wrote (0x6031): the pins' mask, their levels.
    pub(crate) outputs: Option<(u16, u16)>,
    /// The PVT run the bus side started or ended.
    pub(crate) run: Option<RunOrder>,
    /// The PVT queue as the bus side set it (its head and length: emptied, or a run's first
    /// points taken when it started), before the points pushed since.
    pub(crate) queue: Option<(u16, u16)>,
    /// PVT points pushed since the last sync (after `queue`'s).
    pub(crate) pushed: u16,
    /// The watch the bus side armed for its plan (`Some(Some(..))`) or cancelled (`Some(None)`).
    pub(crate) watch: Option<Option<Watch>>,
    /// The pins whose external stop a homing suspends, when the bus side changed them.
    pub(crate) suspend: Option<u16>,
    /// Empty the fault history (0x200F = 5).
    pub(crate) clear_history: bool,
    /// What the master last did to the scope.
    pub(crate) scope: Option<ScopeOrder>,
    /// The black box's capture of this number was read.
    pub(crate) black_box_read: Option<u16>,
}

/// What the master did to the scope: the last order stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ScopeOrder {
    /// Armed with a checked configuration.
    Arm(Config),
    /// Stopped.
    Stop,
    /// The capture of this number was read.
    Read(u16),
}

impl ScopeOrder {
    /// Carries the order out on `scope`.
    pub(crate) fn apply(self, scope: &mut crate::scope::Recorder) {
        match self {
            ScopeOrder::Arm(c) => {
                let _ = scope.arm(&c);
            }
            ScopeOrder::Stop => scope.stop(),
            ScopeOrder::Read(n) => scope.acknowledge(n),
        }
    }
}

impl Orders {
    /// The output pins `mask` written to `levels`, after what was written before.
    pub(crate) fn write_outputs(&mut self, mask: u16, levels: u16) {
        let (m, l) = self.outputs.unwrap_or((0, 0));
        self.outputs = Some((m | mask, (l & !mask) | (levels & mask)));
    }

    /// The PVT queue set to `pvt`'s head and length, the points pushed before it taken in.
    pub(crate) fn set_queue(&mut self, pvt: &Pvt) {
        (self.queue, self.pushed) = (Some((pvt.head, pvt.len)), 0);
    }
}

/// A PVT run the bus side started or ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum RunOrder {
    /// Started: the run, and the pointer of its first point (0x2112).
    Start(Run, u16),
    /// Ended: a stop, the power stage off.
    End,
}

/// The bus side's model of the controller, lent to the tick until a sync has taken it in.
#[derive(Debug)]
pub struct Lent<'a> {
    pub(crate) model: &'a mut Controller,
    /// The bus side's settings: the tick takes them when they changed ([`Orders::settings`]).
    pub(crate) settings: &'a Settings,
    pub(crate) pvt: &'a mut Pvt,
    pub(crate) base: &'a mut Base,
    pub(crate) orders: &'a mut Orders,
    /// A frame for the drive arrived since the last sync (the watchdog restarts).
    pub(crate) heard: &'a mut bool,
}

/// How a sync went.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Handover {
    /// The plan lent starts at a later tick: nothing was done, the model stays lent.
    Waiting,
    /// Synced: the model is the bus side's again.
    Done,
    /// Synced, and the bus side's plan took over at its first tick.
    Planned,
    /// Synced, but the plan took over this many ticks after its first (the bus side was late:
    /// ticks gave setpoints of the old course from the plan's first on).
    Late(u32),
    /// Synced, but the plan was dropped: the tick changed course on its own since the bus side
    /// planned (its stop stands).
    Dropped,
}

impl Controller {
    /// Takes in the bus side's model `lent` at `now` (before this tick's work) and tells it what
    /// the tick did; `settings` and `pvt` are the tick's own. See the module.
    pub fn sync(&mut self, settings: &mut Settings, pvt: &mut Pvt, now: Instant, lent: &mut Lent<'_>) -> Handover {
        let Lent { model, settings: bus_settings, pvt: model_pvt, base, orders, heard } = lent;
        let planned = model.axis.version() != base.version && !orders.stop;
        let starts = if planned { model.axis.activation() } else { None };
        if starts.is_some_and(|at| now < at) {
            return Handover::Waiting;
        }
        let Orders {
            stop,
            settings: changed,
            clear,
            outputs,
            run,
            queue,
            pushed,
            watch,
            suspend,
            clear_history,
            scope,
            black_box_read,
        } = core::mem::take(*orders);
        if clear_history {
            self.faults.clear_history();
        }
        if let Some(order) = scope {
            order.apply(&mut self.scopes.scope);
        }
        if let Some(n) = black_box_read {
            self.scopes.black_box.acknowledge(n);
        }
        // The bus side's settings, whole, when they changed. The zero offset is the tick's own
        // once its closed loop set it at its first reading: the settings' only if the bus side
        // changed that one.
        if changed {
            if bus_settings.zero_offset != settings.zero_offset {
                self.zero_offset = bus_settings.zero_offset;
            }
            *settings = **bus_settings;
        }
        self.heard |= core::mem::take(*heard);
        // A watch belongs to its plan (its version), and comes with it.
        if let Some(watch) = watch {
            self.watch = watch;
        }
        if let Some(pins) = suspend {
            self.suspend = pins;
        }
        clear.clear(&mut self.status, pvt);
        if let Some((mask, levels)) = outputs {
            let s = &mut self.status;
            s.gpio_out = (s.gpio_out & !mask) | (levels & mask);
            s.gpio = (s.gpio & !mask) | (levels & mask);
        }
        match run {
            Some(RunOrder::Start(run, pointer)) => (self.run, self.status.pvt_pointer) = (Some(run), pointer),
            Some(RunOrder::End) => self.run = None,
            None => {}
        }
        // A queue the bus side set is taken whole; points pushed since are appended to what the
        // tick has left.
        if let Some((head, len)) = queue {
            (pvt.head, pvt.len) = (head, len);
        }
        pvt.len = pvt.len.saturating_add(pushed);
        let mut took = false;
        let handover = if stop {
            self.axis.stop_ramp(settings.stop_decel);
            Handover::Done
        } else if !planned {
            Handover::Done
        } else if self.axis.version() != base.version {
            Handover::Dropped
        } else {
            // Late if a tick already gave a setpoint at or after the plan's first (on the old
            // course); a board whose tick is slower than the drive's grid takes every plan at its
            // first tick after the plan's first, as it takes every other sample. A move appended
            // to the one under way is never late: the course is the same until it is reached.
            let late = match (starts, self.axis.last_tick()) {
                (Some(at), Some(last)) if last >= at && !model.axis.appends() => Some(last.since(at) / TICK_MICROS + 1),
                _ => None,
            };
            took = self.axis.take_plan(&model.axis);
            late.map_or(Handover::Planned, |n| Handover::Late(n as u32))
        };
        self.up(model, took);
        (model_pvt.head, model_pvt.len, model_pvt.fault) = (pvt.head, pvt.len, pvt.fault);
        base.version = self.axis.version();
        handover
    }
}

impl Controller {
    /// The tick's state into the bus side's `model` (the track stays the model's: the tick's is
    /// the same, or a dropped plan's that nothing walks; of an axis that just `took` the model's
    /// plan, only the last tick; the watch, which only the tick reads, stays as the bus side
    /// ordered it). Out of line: as arguments the two are known apart, and their fields copy as
    /// plain copies, not as moves of what may overlap.
    #[inline(never)]
    fn up(&mut self, model: &mut Controller, took: bool) {
        model.zero_offset = self.zero_offset;
        if took {
            model.axis.follow_tick_of(&self.axis);
        } else {
            model.axis.follow_walk_of(&self.axis);
        }
        model.status = self.status;
        (model.faults, model.clear_history) = (self.faults, false);
        model.commanded = self.commanded;
        model.probe = self.probe;
        model.servo = self.servo;
        model.run = self.run;
        model.still_since = self.still_since;
        model.shaping_settled = self.shaping_settled;
        model.scopes = self.scopes;
        model.caught = self.caught.take().or(model.caught);
        model.events = Events(model.events.0 | core::mem::take(&mut self.events).0);
    }
}

/// What the control tick owns where it runs apart from the bus side: the settings it runs (a
/// copy of the bus side's, replaced whole when they change), its controller and its PVT queue
/// (the points themselves are in the [`Shared`] table).
#[derive(Clone, Debug)]
pub struct TickSide {
    settings: Settings,
    ctl: Controller,
    pvt: Pvt,
    /// The alarm count at the last tick, to tell a new alarm.
    alarms: u16,
}

impl TickSide {
    /// The tick's side of a drive whose state holds the settings `settings`, the model `ctl`
    /// and the queue `pvt`, before the first tick (all still equal).
    pub fn new(settings: &Settings, ctl: &Controller, pvt: &Pvt) -> Self {
        Self { settings: *settings, ctl: ctl.clone(), pvt: *pvt, alarms: ctl.faults.count }
    }

    /// [`Controller::sync`] with the model `lent`.
    pub fn sync(&mut self, now: Instant, lent: &mut Lent<'_>) -> Handover {
        self.ctl.sync(&mut self.settings, &mut self.pvt, now, lent)
    }

    /// One control tick ([`Controller::tick`]) of the settings in force with the PVT points
    /// and recordings of `shared`.
    pub fn tick(&mut self, now: Instant, inputs: &Inputs, shared: &Shared) -> Outputs {
        self.ctl.tick(&self.settings, now, inputs, &mut self.pvt, shared)
    }

    /// The settings the tick runs.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Whether the bus side should sync soon without waiting for a request: power is failing
    /// (the position save), an alarm was recorded (the history save), a watch caught what it
    /// waited for (the next step of a homing), or an input turned active (its function). Once a
    /// tick.
    pub fn needs_bus(&mut self) -> bool {
        let alarms = core::mem::replace(&mut self.alarms, self.ctl.faults.count);
        let e = self.ctl.events;
        e.has(Events::POWER_FAILING) || e.has(Events::CAUGHT) || e.has(Events::INPUT) || alarms != self.alarms
    }

    /// The controller the tick runs.
    pub fn controller(&self) -> &Controller {
        &self.ctl
    }
}

#[cfg(test)]
mod tests {
    use super::Orders;

    #[test]
    fn output_writes_add_up_the_latest_level_winning() {
        let mut o = Orders::default();
        o.write_outputs(0b0011, 0b0001);
        o.write_outputs(0b0110, 0b0110);
        assert_eq!(o.outputs, Some((0b0111, 0b0111)));
    }
}
