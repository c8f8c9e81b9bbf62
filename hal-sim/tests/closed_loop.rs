//! The closed loop on the physical motor model, the motor's currents from the ideal chopper
//! (`suites/closed_loop.rs`).

/// The power stage the suite runs on.
const STAGE: hal_sim::bridges::PowerStage = hal_sim::bridges::PowerStage::Chopper;

include!("suites/closed_loop.rs");
