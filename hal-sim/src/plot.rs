//! PNG plots of motion traces ([`crate::trace`]), with `plotters`.
//!
//! Four panels over time: position (commanded and rotor), following error (commanded − rotor,
//! where lost steps show as a jump of 4 full steps at a time), velocity (commanded and rotor) and
//! the two phase currents with the current vector's magnitude (which falls at speed, when the
//! supply can no longer push the commanded current through the winding).
//!
//! Pull-out torque against speed ([`plot_torque_speed`], [`crate::torque_speed`]): a panel a
//! motor, the chopper's and the bridges' curves at each supply.
//!
//! Any panels of lines over time ([`plot_panels`]): what the trace's figure is drawn with, and
//! `drivectl scope` draws a capture of the drive's own scope with.
//!
//! Text is drawn with `plotters`' `ab_glyph` feature and the DejaVu Sans font compiled in (the
//! `dejavu` crate), so plotting needs no system font, fontconfig or freetype.

use std::fmt;
use std::ops::Range;
use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::types::RangedCoordf64;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::register_font;

pub use plotters::style::RGBColor;

use crate::bridges::PowerStage;
use crate::torque_speed::Curve;
use crate::trace::{TraceRow, load_csv};

/// Why a plot could not be drawn.
#[derive(Debug)]
pub struct PlotError(String);

impl fmt::Display for PlotError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "cannot plot the trace: {}", self.0)
    }
}

impl std::error::Error for PlotError {}

fn err(e: impl fmt::Display) -> PlotError {
    PlotError(e.to_string())
}

/// The font family every text of the plots uses (registered on first use).
const FONT: &str = "sans-serif";

fn register_fonts() -> Result<(), PlotError> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
            && register_font(FONT, FontStyle::Bold, dejavu::sans::bold()).is_ok()
    });
    if ok { Ok(()) } else { Err(PlotError("the embedded font did not load".into())) }
}

/// The range of the values, padded by 5 % (and widened around a constant).
fn padded(values: impl Iterator<Item = f64>) -> Range<f64> {
    let (lo, hi) =
        values.filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return -1.0..1.0;
    }
    let pad = ((hi - lo) * 0.05).max(1e-9 + lo.abs().max(hi.abs()) * 1e-6).max(if hi == lo { 1.0 } else { 0.0 });
    (lo - pad)..(hi + pad)
}

const COMMANDED: RGBColor = RGBColor(30, 90, 200);
const ROTOR: RGBColor = RGBColor(220, 50, 30);
const PHASE_A: RGBColor = RGBColor(30, 90, 200);
const PHASE_B: RGBColor = RGBColor(20, 150, 60);

/// Colours for a panel's lines, in order.
pub const COLOURS: [RGBColor; 4] = [COMMANDED, ROTOR, PHASE_B, RGBColor(120, 60, 160)];

/// One line of a panel: label, colour, width in pixels, (time, value) points.
pub type Series<'a> = (&'a str, RGBColor, u32, Vec<(f64, f64)>);

/// One panel: a few series against time.
pub struct Panel<'a> {
    /// Its caption.
    pub title: String,
    /// The y axis' description.
    pub y_desc: &'a str,
    /// Its lines.
    pub series: Vec<Series<'a>>,
}

/// Draws the trace to a PNG file (1200 × 1400 pixels), titled `title`.
pub fn plot_trace(rows: &[TraceRow], png: impl AsRef<Path>, title: &str) -> Result<(), PlotError> {
    if rows.is_empty() {
        return Err(PlotError("the trace is empty".into()));
    }
    register_fonts()?;
    let t = |f: fn(&TraceRow) -> f64| rows.iter().map(|r| (r.t_s, f(r))).collect::<Vec<_>>();
    let last = rows[rows.len() - 1];
    let final_error = last.commanded_position_usteps - last.rotor_position_usteps;
    let max_error =
        rows.iter().map(|r| (r.commanded_position_usteps - r.rotor_position_usteps).abs()).fold(0.0, f64::max);
    let panels = [
        Panel {
            title: "Position".into(),
            y_desc: "position (µsteps)",
            series: vec![
                ("commanded", COMMANDED, 3, t(|r| r.commanded_position_usteps)),
                ("rotor", ROTOR, 1, t(|r| r.rotor_position_usteps)),
            ],
        },
        Panel {
            title: format!("Following error: final {final_error:.1} µsteps, largest |error| {max_error:.1} µsteps"),
            y_desc: "commanded − rotor (µsteps)",
            series: vec![("error", ROTOR, 1, t(|r| r.commanded_position_usteps - r.rotor_position_usteps))],
        },
        Panel {
            title: "Velocity".into(),
            y_desc: "velocity (µsteps/s)",
            series: vec![
                ("commanded", COMMANDED, 3, t(|r| r.commanded_velocity_pps)),
                ("rotor", ROTOR, 1, t(|r| r.rotor_velocity_pps)),
            ],
        },
        Panel {
            title: "Phase currents".into(),
            y_desc: "current (A)",
            series: vec![
                ("i_a", PHASE_A, 1, t(|r| r.i_a)),
                ("i_b", PHASE_B, 1, t(|r| r.i_b)),
                ("|i| = √(i_a² + i_b²)", BLACK, 2, t(|r| r.i_a.hypot(r.i_b))),
            ],
        },
    ];

    plot_panels(&panels, png, title)
}

/// Draws `panels` one above the other against time (s) to a PNG file (1200 pixels wide, 350 a
/// panel), titled `title`. The time axis starts at 0 unless a point is before it.
pub fn plot_panels(panels: &[Panel<'_>], png: impl AsRef<Path>, title: &str) -> Result<(), PlotError> {
    let times = || panels.iter().flat_map(|p| p.series.iter().flat_map(|s| s.3.iter().map(|p| p.0)));
    let first = times().fold(f64::INFINITY, f64::min);
    if !first.is_finite() {
        return Err(PlotError("nothing to plot".into()));
    }
    register_fonts()?;
    let height = 350 * u32::try_from(panels.len()).unwrap_or(1).max(1);
    let root = BitMapBackend::new(png.as_ref(), (1200, height)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(title, (FONT, 28).into_font().style(FontStyle::Bold)).map_err(err)?;
    let time = padded(times());
    let time = first.min(time.start.max(0.0))..time.end;
    for (area, panel) in root.split_evenly((panels.len(), 1)).iter().zip(panels) {
        let y = padded(panel.series.iter().flat_map(|s| s.3.iter().map(|p| p.1)));
        let span = y.end - y.start;
        let decimals = if span >= 50.0 {
            0
        } else if span >= 5.0 {
            1
        } else if span >= 0.5 {
            2
        } else {
            4
        };
        let y_label = move |v: &f64| format!("{v:.decimals$}");
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, (FONT, 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(90)
            .build_cartesian_2d(time.clone(), y)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_desc(panel.y_desc)
            .y_label_formatter(&y_label)
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 16))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(err)?;
        draw_lines(&mut chart, &panel.series, SeriesLabelPosition::UpperLeft)?;
    }
    root.present().map_err(err)
}

/// Reads a trace CSV ([`crate::trace::load_csv`]) and draws it to a PNG file with
/// [`plot_trace`], titled with the CSV's file name.
pub fn plot_trace_csv(csv: impl AsRef<Path>, png: impl AsRef<Path>) -> Result<(), PlotError> {
    let csv = csv.as_ref();
    let rows = load_csv(csv).map_err(|e| PlotError(format!("{}: {e}", csv.display())))?;
    let title = csv.file_name().map_or_else(|| csv.display().to_string(), |n| n.to_string_lossy().into_owned());
    plot_trace(&rows, png, &title)
}

/// Draws the path of two axes against each other (x from `x`, y from `y`, row by row: traces of
/// two drives on one bus, recorded at the same ticks) to a square PNG (900 × 900 pixels): the
/// commanded path and the rotors' path.
pub fn plot_xy(x: &[TraceRow], y: &[TraceRow], png: impl AsRef<Path>, title: &str) -> Result<(), PlotError> {
    if x.is_empty() || y.is_empty() {
        return Err(PlotError("a trace is empty".into()));
    }
    register_fonts()?;
    let path = |f: fn(&TraceRow) -> f64| x.iter().zip(y).map(|(a, b)| (f(a), f(b))).collect::<Vec<_>>();
    let commanded = path(|r| r.commanded_position_usteps);
    let rotor = path(|r| r.rotor_position_usteps);
    // One scale on both axes, so that a circle looks round.
    let (xr, yr) = (padded(commanded.iter().map(|p| p.0)), padded(commanded.iter().map(|p| p.1)));
    let half = (xr.end - xr.start).max(yr.end - yr.start) / 2.0;
    let (cx, cy) = ((xr.start + xr.end) / 2.0, (yr.start + yr.end) / 2.0);
    let root = BitMapBackend::new(png.as_ref(), (900, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT, 24).into_font().style(FontStyle::Bold))
        .margin(16)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d((cx - half)..(cx + half), (cy - half)..(cy + half))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("axis 1 (µsteps)")
        .y_desc("axis 2 (µsteps)")
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 16))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(err)?;
    let series = [("commanded", COMMANDED, 4, commanded), ("rotor", ROTOR, 1, rotor)];
    draw_lines(&mut chart, &series, SeriesLabelPosition::UpperRight)?;
    root.present().map_err(err)
}

/// A supply's colour in [`plot_torque_speed`], in the order of the supplies.
const SUPPLY_COLOURS: [RGBColor; 4] =
    [RGBColor(30, 90, 200), RGBColor(20, 150, 60), RGBColor(220, 50, 30), RGBColor(120, 60, 160)];

/// Draws pull-out torque against speed ([`crate::torque_speed`]) to a PNG (1400 × 650 pixels),
/// titled `title`: a panel a motor, a colour a supply, the chopper's curves solid and the
/// bridges' dashed.
pub fn plot_torque_speed(curves: &[Curve], png: impl AsRef<Path>, title: &str) -> Result<(), PlotError> {
    if curves.iter().all(|c| c.points.is_empty()) {
        return Err(PlotError("no curve has a point".into()));
    }
    register_fonts()?;
    let mut motors: Vec<&str> = Vec::new();
    let mut supplies: Vec<f64> = Vec::new();
    for c in curves {
        if !motors.contains(&c.setup.motor.name.as_str()) {
            motors.push(&c.setup.motor.name);
        }
        if !supplies.contains(&c.setup.supply_v) {
            supplies.push(c.setup.supply_v);
        }
    }
    supplies.sort_by(f64::total_cmp);
    let root = BitMapBackend::new(png.as_ref(), (1400, 650)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root.titled(title, (FONT, 24).into_font().style(FontStyle::Bold)).map_err(err)?;
    for (area, &motor) in root.split_evenly((1, motors.len())).iter().zip(&motors) {
        let mine: Vec<&Curve> = curves.iter().filter(|c| c.setup.motor.name == motor).collect();
        let points = || mine.iter().flat_map(|c| c.points.iter());
        // Room above the curves for the legend.
        let top = points().map(|p| p.torque_nm).fold(0.0, f64::max).max(1e-3) * 1.45;
        let right = points().map(|p| p.speed_rps).fold(0.0, f64::max).max(1.0);
        let holding = mine.first().map_or(0.0, |c| c.setup.holding_nm());
        let current = mine.first().map_or(0.0, |c| f64::from(c.setup.current_ma()) * 1e-3);
        let mut chart = ChartBuilder::on(area)
            .caption(format!("{motor}: K_m·I = {holding:.3} N·m at {current:.1} A"), (FONT, 20))
            .margin(14)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..right, 0.0..top)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("speed (rev/s)")
            .y_desc("pull-out torque (N·m)")
            .x_label_formatter(&|v: &f64| format!("{v:.0}"))
            .y_label_formatter(&|v: &f64| format!("{v:.2}"))
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 16))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()
            .map_err(err)?;
        for curve in mine {
            let k = supplies.iter().position(|&v| v == curve.setup.supply_v).unwrap_or(0);
            let colour = SUPPLY_COLOURS[k % SUPPLY_COLOURS.len()];
            let line: Vec<(f64, f64)> = curve.points.iter().map(|p| (p.speed_rps, p.torque_nm)).collect();
            let label = format!(
                "{} V, {}",
                curve.setup.supply_v,
                match curve.setup.stage {
                    PowerStage::Chopper => "chopper",
                    PowerStage::Bridges => "bridges",
                }
            );
            let style = colour.stroke_width(2);
            match curve.setup.stage {
                PowerStage::Chopper => {
                    chart
                        .draw_series(LineSeries::new(line.iter().copied(), style))
                        .map_err(err)?
                        .label(label)
                        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 28, y)], style));
                }
                PowerStage::Bridges => {
                    chart
                        .draw_series(DashedLineSeries::new(line.iter().copied(), 9, 6, style))
                        .map_err(err)?
                        .label(label)
                        .legend(move |(x, y)| DashedPathElement::new(vec![(x, y), (x + 28, y)], 9, 6, style));
                }
            }
            let marker = |&(v, t): &(f64, f64)| Circle::new((v, t), 3, colour.filled());
            chart.draw_series(line.iter().map(marker)).map_err(err)?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .label_font((FONT, 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)
}

/// Draws each series as a line with its legend entry, then the legend at `position`.
fn draw_lines<'a>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    series: &[Series<'_>],
    position: SeriesLabelPosition,
) -> Result<(), PlotError> {
    for (label, color, width, points) in series {
        let style = color.stroke_width(*width);
        chart
            .draw_series(LineSeries::new(points.iter().copied(), style))
            .map_err(err)?
            .label(*label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
    }
    chart
        .configure_series_labels()
        .position(position)
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(err)
}
