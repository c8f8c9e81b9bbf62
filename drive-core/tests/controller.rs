//! The controller on its own: settings in, a tick with measurements, outputs and events out, with
//! no drive, dictionary or bus around it.

use drive_core::controller::Shared;
use drive_core::controller::{Controller, Events, Pvt, Settings};
use drive_core::faults::{COMM_TIMEOUT, ERR_UNDER_VOLTAGE, Inputs};
use drive_core::modes::PowerState;
use drive_core::motion::scurve::Limits;
use drive_core::servo::Feedback;
use drive_core::units::TICK_MICROS;
use drive_core::{Drive, Instant};

/// The factory settings, enabled, with `f` applied, and a controller at power-up with them.
fn controller(f: impl FnOnce(&mut Settings)) -> (Settings, Controller) {
    let mut settings = *Drive::factory().state().settings();
    settings.enabled = true;
    f(&mut settings);
    (settings, Controller::new(&settings, Feedback::Open))
}

fn at(k: u64) -> Instant {
    Instant::from_micros(k * TICK_MICROS)
}

#[test]
fn standing_it_drops_to_the_standstill_current_after_the_delay() {
    let (settings, mut c) = controller(|s| {
        (s.phase_current_ma, s.idle_current_pct, s.idle_delay_us) = (1_000, 40, 100_000);
    });
    let (mut pvt, table) = (Pvt::default(), Shared::new());
    let first = c.tick(&settings, at(0), &Inputs::default(), &mut pvt, &table);
    assert_eq!((first.enabled, first.current_ma), (true, 1_000));
    let later = c.tick(&settings, at(2_000), &Inputs::default(), &mut pvt, &table);
    assert_eq!(later.current_ma, 400, "40 % of 1000 mA after 100 ms standing");
    assert!(c.take_events().is_empty());
}

#[test]
fn the_watchdog_ramps_a_run_down_and_reports_the_stop() {
    let (settings, mut c) = controller(|s| (s.comm_timeout_us, s.stop_decel) = (100_000, 20_000));
    let limits = Limits { v_max: 4_000.0, a_max: 40_000.0, d_max: 40_000.0, jerk: None };
    assert!(c.axis_mut().run_at(at(0), 4_000.0, 0.0, &limits).is_ok());
    let (mut pvt, table) = (Pvt::default(), Shared::new());
    let mut k = 0;
    while c.status().comm & COMM_TIMEOUT == 0 {
        c.tick(&settings, at(k), &Inputs::default(), &mut pvt, &table);
        k += 1;
        assert!(k <= 2_001, "the watchdog runs out 100 ms after the first tick");
    }
    assert_eq!(k, 2_001);
    assert!(c.take_events().has(Events::STOPPED));
    // 4000 pps at 20 000 pps²: 0.2 s of ramp, then it stands.
    for _ in 0..4_100 {
        c.tick(&settings, at(k), &Inputs::default(), &mut pvt, &table);
        k += 1;
    }
    assert!(c.axis().is_still());
}

#[test]
fn a_fault_latches_and_frees_the_motor() {
    let (settings, mut c) = controller(|s| s.under_voltage_mv = 18_000);
    let (mut pvt, table) = (Pvt::default(), Shared::new());
    let low = Inputs { supply_mv: Some(12_000), ..Inputs::default() };
    let out = c.tick(&settings, at(0), &low, &mut pvt, &table);
    assert_eq!((out.enabled, out.current_ma), (false, 0));
    assert_eq!(c.status().error & ERR_UNDER_VOLTAGE, ERR_UNDER_VOLTAGE);
    assert_eq!(c.power_state(&settings), PowerState::Faulted);
    // Latched: the supply coming back does not clear it.
    let ok = Inputs { supply_mv: Some(24_000), ..Inputs::default() };
    assert!(!c.tick(&settings, at(1), &ok, &mut pvt, &table).enabled);
}
