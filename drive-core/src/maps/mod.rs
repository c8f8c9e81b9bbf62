//! Register maps: how a master's registers reach the drive's objects. [`native`] is the drive's
//! own map (seed 000), indexed at compile time; [`layout`] serves any other map from a table of
//! addresses, word orders, scales and exception codes over the same objects.

pub mod index;
pub mod layout;
pub mod native;

pub use native::{NativeMap, RegisterMap};
