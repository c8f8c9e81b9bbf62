//! Motion: profiles planned once and evaluated by time at every control tick.

pub mod axis;
pub mod cubic;
pub mod scurve;
pub mod track;
