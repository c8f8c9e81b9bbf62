//! The scope's and the black box's objects (0x2220-0x2240): the configuration a master arms
//! the scope with, its orders to the tick, what the recorders say, and the captures' rows.

use super::{DriveState, ProgramMemory};
use crate::controller::Shared;
use crate::controller::handoff::ScopeOrder;
use crate::od::{Obj, ObjError};
use crate::scope::{Config, MAX_SIGNALS, Recorder, Signal, Trigger};
use core::borrow::Borrow;

/// The scope's signal objects (0x2220-0x2227), in a row's order.
pub const SIGNALS: [Obj; MAX_SIGNALS] = [
    Obj::ScopeSignal1,
    Obj::ScopeSignal2,
    Obj::ScopeSignal3,
    Obj::ScopeSignal4,
    Obj::ScopeSignal5,
    Obj::ScopeSignal6,
    Obj::ScopeSignal7,
    Obj::ScopeSignal8,
];

/// Whether writing `obj` orders the scope or the black box.
pub(crate) const fn is_order(obj: Obj) -> bool {
    matches!(obj, Obj::ScopeControl | Obj::ScopeRead | Obj::BlackBoxRead)
}

/// The first register of the scope's capture window in the native map (8192 registers).
pub const SCOPE_WINDOW: u16 = 0x4000;
/// The first register of the black box's capture window in the native map (8192 registers).
pub const BLACK_BOX_WINDOW: u16 = 0xA000;

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// The scope's configuration as 0x2220-0x222E hold it.
    pub(crate) fn scope_config(&self) -> Config {
        let signal = |obj| Signal::from_code(self.param(obj) as u16).unwrap_or(Signal::None);
        let mut signals = [Signal::None; MAX_SIGNALS];
        for (slot, obj) in signals.iter_mut().zip(SIGNALS) {
            *slot = signal(obj);
        }
        let kind = self.param(Obj::ScopeTrigger) as u16;
        let level = self.param(Obj::ScopeTriggerLevel) as i32;
        Config {
            signals,
            divider: self.param(Obj::ScopeDivider) as u16,
            trigger: Trigger::from_code(kind, signal(Obj::ScopeTriggerSignal), level).unwrap_or(Trigger::Now),
            pre_percent: self.param(Obj::ScopePreTrigger) as u8,
            repeat: self.param(Obj::ScopeMode) == 1,
        }
    }

    /// Whether the order `value` to `obj` is taken: arming needs a signal, and a trigger that
    /// watches a signal needs one named.
    pub(crate) fn check_order(&self, obj: Obj, value: u32) -> Result<(), ObjError> {
        match (obj, value) {
            (Obj::ScopeControl, 1) => Recorder::new().arm(&self.scope_config()).map_err(|_| ObjError::NotNow),
            _ => Ok(()),
        }
    }

    /// Carries out the order `value` to `obj` on the model, and orders the tick to.
    pub(crate) fn apply_order(&mut self, obj: Obj, value: u32) {
        self.set_param(obj, value);
        let n = value as u16;
        if obj == Obj::BlackBoxRead {
            self.ctl.scopes.black_box.acknowledge(n);
            self.orders.black_box_read = Some(n);
            return;
        }
        let order = match (obj, value) {
            (Obj::ScopeControl, 1) => ScopeOrder::Arm(self.scope_config()),
            (Obj::ScopeControl, _) => ScopeOrder::Stop,
            _ => ScopeOrder::Read(n),
        };
        order.apply(&mut self.ctl.scopes.scope);
        self.orders.scope = Some(order);
    }

    /// What the scope's and the black box's read-only objects say.
    pub(crate) fn recording_live(&self, obj: Obj) -> u32 {
        let (scope, black_box) = (&self.ctl.scopes.scope, &self.ctl.scopes.black_box);
        u32::from(match obj {
            Obj::ScopeState => scope.phase() as u16,
            Obj::ScopeSequence => scope.sequence(),
            Obj::ScopeRows => scope.len(),
            Obj::ScopeRowWords => scope.row_words(),
            Obj::ScopeTriggerRow => scope.trigger_row(),
            Obj::BlackBoxState => black_box.phase() as u16,
            Obj::BlackBoxSequence => black_box.sequence(),
            Obj::BlackBoxRows => black_box.len(),
            Obj::BlackBoxTriggerRow => black_box.trigger_row(),
            Obj::BlackBoxFault if !black_box.is_empty() => return self.ctl.scopes.black_box_fault,
            Obj::ScopeRowPeriod => return scope.period_us(),
            Obj::BlackBoxRowPeriod => return black_box.period_us(),
            _ => 0,
        })
    }

    /// Word `k` of the scope's capture (`black_box`: the black box's), its rows in time order;
    /// `None` past its memory.
    pub fn capture_word(&self, black_box: bool, k: usize) -> Option<u16> {
        let (scopes, memory) = (&self.ctl.scopes, &self.shared.borrow().recordings);
        if black_box { scopes.black_box.word(&memory.black_box, k) } else { scopes.scope.word(&memory.scope, k) }
    }

    /// The native map's capture windows: register `addr`'s word, if it lies in one.
    pub(crate) fn window_word(&self, addr: u32) -> Option<u16> {
        let (scope, black_box) = (u32::from(SCOPE_WINDOW), u32::from(BLACK_BOX_WINDOW));
        match addr {
            a if (scope..scope + crate::scope::WORDS as u32).contains(&a) => {
                self.capture_word(false, (a - scope) as usize)
            }
            a if (black_box..black_box + crate::scope::WORDS as u32).contains(&a) => {
                self.capture_word(true, (a - black_box) as usize)
            }
            _ => None,
        }
    }
}
