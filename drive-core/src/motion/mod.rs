//! Motion: profiles planned once, outside the tick, and walked in integers a sample at every
//! control tick.

pub mod axis;
pub mod cubic;
pub mod scurve;
pub mod shaping;
pub mod track;
pub mod whole;
