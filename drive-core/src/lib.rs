//! The logic of an integrated stepper drive that is a Modbus-RTU slave.
//!
//! `drive-core` is a pure state machine: bytes and time go in, reply frames come out. It has no
//! I/O, no allocation and no global state, so the same code runs on the STM32 (crate `firmware`)
//! and against the simulated motor on a host (crate `hal-sim`).
//!
//! ```
//! use drive_core::{Drive, Instant};
//! let mut drive = Drive::factory();
//! // Read 0x600C..0x600D (microstep resolution and phase current) from node 1.
//! drive.on_rx(Instant::from_micros(0), &[0x01, 0x03, 0x60, 0x0C, 0x00, 0x02, 0x1A, 0x08]);
//! // Nothing is answered before the line has been quiet for t3.5 (4.01 ms at 9600 baud).
//! drive.on_timer(Instant::from_micros(4_000));
//! assert_eq!(drive.take_reply(), None);
//! drive.on_timer(Instant::from_micros(4_011));
//! // Factory defaults: resolution 0, phase current 658 mA (0x0292).
//! assert_eq!(drive.take_reply(), Some(&[0x01, 0x03, 0x04, 0x00, 0x00, 0x02, 0x92, 0x7A, 0xFE][..]));
//! ```
#![no_std]
#![forbid(unsafe_code)]
#![deny(clippy::unwrap_used, clippy::expect_used, clippy::panic, clippy::indexing_slicing, missing_docs)]

pub mod ascii;
pub mod autotune;
pub mod controller;
pub mod crc;
pub mod current;
pub mod drive;
pub mod faults;
pub mod ident;
pub mod maps;
pub mod math;
pub mod modes;
pub mod motion;
pub mod od;
pub mod pdu;
pub mod power;
pub mod rtu;
pub mod scope;
pub mod servo;
pub mod state;
pub mod store;
pub mod units;
pub mod update;
pub mod windings;

pub use drive::{Drive, DriveConfig};
pub use pdu::Exception;
pub use state::{DriveState, Params, SystemRequest, control, pvt};
pub use units::{Baud, Instant, SlaveAddr};
