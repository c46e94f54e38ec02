//! Results for people: a metrics table for the terminal, per-tick traces as CSV, and plots of
//! target vs response and current as SVG (plotters; no system fonts needed).

use crate::scenario::{ChassisSample, RunResult, Scenario, TargetKind};
use plotters::prelude::*;
use rc10_core::chassis::Twist;
use std::fmt::Write as _;
use std::io;
use std::path::{Path, PathBuf};

fn opt_ms(v: Option<f64>) -> String {
    v.map_or_else(|| "never".to_string(), |s| format!("{:.1} ms", s * 1e3))
}

/// A value rounded to a whole number, without a "-0".
fn whole(v: f64) -> String {
    let r = v.round();
    format!("{}", if r == 0.0 { 0.0 } else { r })
}

fn unit(kind: TargetKind) -> &'static str {
    match kind {
        TargetKind::Current => "A",
        TargetKind::Rpm => "rpm",
        TargetKind::AngleDeg | TargetKind::TotalAngleDeg => "deg",
    }
}

/// The metrics table and bus summary as text.
pub fn summary(scenario: &Scenario, result: &RunResult) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "scenario  {}: {}", scenario.name, scenario.description);
    let _ = writeln!(
        s,
        "simulated {} ms, seed {}, {} motor(s)\n",
        scenario.duration_ms,
        scenario.seed,
        scenario.motors.len()
    );
    let _ = writeln!(
        s,
        "{:<6} {:>14} {:>10} {:>10} {:>10} {:>12} {:>10} {:>9}",
        "motor", "step", "rise", "overshoot", "settle 2%", "steady err", "IAE", "peak I"
    );
    for m in &result.metrics {
        let x = &m.metrics;
        let u = unit(m.kind);
        let _ = writeln!(
            s,
            "{:<6} {:>14} {:>10} {:>9.2}% {:>10} {:>8.3} {:<3} {:>10.3} {:>7.2} A",
            m.motor + 1,
            format!("{}->{} {u}", whole(x.initial), whole(x.target)),
            opt_ms(x.rise_time_s),
            x.overshoot_percent,
            opt_ms(x.settling_time_s),
            x.steady_state_error,
            u,
            x.iae,
            x.peak_current_amps
        );
    }
    if let Some(t) = chassis_summary(scenario, result) {
        s.push_str(&t);
    }
    let c = &result.counters;
    let bus_load = 100.0 * result.bus.busy_us as f64 / (scenario.duration_ms as f64 * 1e3);
    let _ = writeln!(
        s,
        "\nbus       load {bus_load:.1} % (budget: nominal {:.1} %, worst case {:.1} %), {} frames",
        result.budget.nominal_load_percent,
        result.budget.worst_case_load_percent,
        result.bus.frames
    );
    let _ = writeln!(
        s,
        "rc10      rx {} (unmatched {}, rejected {}), tx {} (dropped {}, sent late {}), offline events {:?}",
        c.rx_frames,
        c.rx_unmatched,
        c.rx_rejected,
        c.tx_frames,
        c.tx_dropped(),
        c.tx_stale,
        result.offline_events
    );
    let _ = writeln!(
        s,
        "faults    frames lost {}, RX FIFO overruns {}, device TX drops {}",
        result.bus.lost, result.rx_overruns, result.bus.device_tx_dropped
    );
    s
}

/// Twist tracking figures of a chassis scenario.
fn chassis_summary(scenario: &Scenario, result: &RunResult) -> Option<String> {
    let drive = scenario.chassis.as_ref()?;
    let c: Vec<(u64, ChassisSample)> = result
        .samples
        .iter()
        .filter_map(|s| s.chassis.map(|c| (s.t_ms, c)))
        .collect();
    let n = c.len().max(1) as f32;
    let rms = |f: &dyn Fn(&ChassisSample) -> f32| {
        (c.iter().map(|(_, x)| f(x) * f(x)).sum::<f32>() / n).sqrt()
    };
    let mut s = String::new();
    let _ = writeln!(
        s,
        "chassis   twist error RMS: vx {:.3} m/s, vy {:.3} m/s, w {:.3} rad/s",
        rms(&|x| x.achieved.vx_m_s - x.commanded.vx_m_s),
        rms(&|x| x.achieved.vy_m_s - x.commanded.vy_m_s),
        rms(&|x| x.achieved.omega_rad_s - x.commanded.omega_rad_s),
    );
    for (from, _) in &drive.radio_off {
        let lost = c
            .iter()
            .find(|(t, x)| t >= from && x.link_lost)
            .map(|(t, _)| *t);
        let stopped = lost.and_then(|l| {
            c.iter()
                .find(|(t, x)| {
                    *t >= l
                        && x.achieved.vx_m_s.hypot(x.achieved.vy_m_s) < 0.05
                        && x.achieved.omega_rad_s.abs() < 0.05
                })
                .map(|(t, _)| *t)
        });
        let _ = writeln!(
            s,
            "          radio off at {from} ms: link lost after {}, chassis stopped after {}",
            lost.map_or("never".into(), |t| format!("{} ms", t - from)),
            stopped.map_or("never".into(), |t| format!("{} ms", t - from)),
        );
    }
    Some(s)
}

/// Writes the per-tick trace as CSV: one row per ms, one column group per motor.
pub fn write_csv(result: &RunResult, path: &Path) -> io::Result<()> {
    let mut out = String::from("t_ms");
    let n = result.samples.first().map_or(0, |s| s.motors.len());
    for m in 1..=n {
        let _ = write!(
            out,
            ",m{m}_target,m{m}_true_rpm,m{m}_measured_rpm,m{m}_true_total_deg,\
             m{m}_measured_total_deg,m{m}_command,m{m}_current_amps,m{m}_temperature_c,m{m}_online"
        );
    }
    let chassis = result.samples.first().is_some_and(|s| s.chassis.is_some());
    if chassis {
        out.push_str(",cmd_vx_m_s,cmd_vy_m_s,cmd_omega_rad_s,vx_m_s,vy_m_s,omega_rad_s,link_lost");
    }
    out.push('\n');
    for s in &result.samples {
        let _ = write!(out, "{}", s.t_ms);
        for m in &s.motors {
            let _ = write!(
                out,
                ",{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.2},{}",
                m.target,
                m.true_rpm,
                m.measured_rpm,
                m.true_total_deg,
                m.measured_total_deg,
                m.command,
                m.current_amps,
                m.temperature_c,
                u8::from(m.online)
            );
        }
        if let Some(c) = s.chassis {
            let _ = write!(
                out,
                ",{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{}",
                c.commanded.vx_m_s,
                c.commanded.vy_m_s,
                c.commanded.omega_rad_s,
                c.achieved.vx_m_s,
                c.achieved.vy_m_s,
                c.achieved.omega_rad_s,
                u8::from(c.link_lost)
            );
        }
        out.push('\n');
    }
    std::fs::write(path, out)
}

fn plot_err(e: impl std::fmt::Display) -> io::Error {
    io::Error::other(e.to_string())
}

/// One plotted instant of one motor.
#[derive(Clone, Copy)]
struct Point {
    t_s: f64,
    target: f64,
    response: f64,
    current_amps: f64,
}

/// The series' combined range of the values `f` picks, padded by 8 %.
fn padded_range(series: &[Vec<Point>], f: impl Fn(&Point) -> [f64; 2]) -> std::ops::Range<f64> {
    let (lo, hi) = series
        .iter()
        .flatten()
        .flat_map(f)
        .fold((0.0f64, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let pad = ((hi - lo) * 0.08).max(1e-3);
    (lo - pad)..(hi + pad)
}

const COLORS: [RGBColor; 6] = [RED, BLUE, GREEN, MAGENTA, CYAN, BLACK];

/// Plots target vs response (top) and current (bottom) for every motor as an SVG.
pub fn write_svg(scenario: &Scenario, result: &RunResult, path: &Path) -> io::Result<()> {
    let root = SVGBackend::new(path, (1000, 640)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let (top, bottom) = root.split_vertically(400);
    let t_end = scenario.duration_ms as f64 * 1e-3;
    let angle = scenario
        .targets
        .iter()
        .any(|t| matches!(t.kind, TargetKind::AngleDeg | TargetKind::TotalAngleDeg));
    let response = |m: &crate::scenario::MotorSample| {
        if angle { m.true_total_deg } else { m.true_rpm }
    };
    let series: Vec<Vec<Point>> = (0..scenario.motors.len())
        .map(|i| {
            result
                .samples
                .iter()
                .filter_map(|s| {
                    s.motors.get(i).map(|m| {
                        let target = match scenario.targets.iter().find(|t| t.motor == i) {
                            Some(t) if t.kind == TargetKind::AngleDeg => {
                                // Show the angle target where the motor is headed.
                                let y = response(m);
                                y + f64::from(rc10_core::math::wrap_deg_180(m.target - y as f32))
                            }
                            _ => f64::from(m.target),
                        };
                        Point {
                            t_s: s.t_ms as f64 * 1e-3,
                            target,
                            response: response(m),
                            current_amps: m.current_amps,
                        }
                    })
                })
                .collect()
        })
        .collect();
    let y_range = padded_range(&series, |p| [p.target, p.response]);
    let i_range = padded_range(&series, |p| [p.current_amps, p.current_amps]);

    let mut chart = ChartBuilder::on(&top)
        .caption(
            format!("{} — target (dashed) and response", scenario.name),
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..t_end, y_range)
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(if angle {
            "output angle (deg)"
        } else {
            "output speed (rpm)"
        })
        .draw()
        .map_err(plot_err)?;
    for (i, (s, &color)) in series.iter().zip(COLORS.iter().cycle()).enumerate() {
        chart
            .draw_series(DashedLineSeries::new(
                s.iter().map(|p| (p.t_s, p.target)),
                6,
                4,
                color.mix(0.6).stroke_width(1),
            ))
            .map_err(plot_err)?;
        chart
            .draw_series(LineSeries::new(
                s.iter().map(|p| (p.t_s, p.response)),
                color.stroke_width(2),
            ))
            .map_err(plot_err)?
            .label(format!("motor {}", i + 1))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color));
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(plot_err)?;

    let mut current = ChartBuilder::on(&bottom)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..t_end, i_range)
        .map_err(plot_err)?;
    current
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc("winding current (A)")
        .draw()
        .map_err(plot_err)?;
    for (s, &color) in series.iter().zip(COLORS.iter().cycle()) {
        current
            .draw_series(LineSeries::new(
                s.iter().map(|p| (p.t_s, p.current_amps)),
                color.stroke_width(1),
            ))
            .map_err(plot_err)?;
    }
    root.present().map_err(plot_err)
}

/// A plotted twist component: its label and how to read it.
type Axis = (&'static str, fn(&Twist) -> f32);

/// Plots commanded (dashed) and achieved twist, one panel per axis, with radio-loss periods
/// shaded.
pub fn write_chassis_svg(scenario: &Scenario, result: &RunResult, path: &Path) -> io::Result<()> {
    let root = SVGBackend::new(path, (1000, 720)).into_drawing_area();
    root.fill(&WHITE).map_err(plot_err)?;
    let panels = root.split_evenly((3, 1));
    let t_end = scenario.duration_ms as f64 * 1e-3;
    let axes: [Axis; 3] = [
        ("vx (m/s)", |t| t.vx_m_s),
        ("vy (m/s)", |t| t.vy_m_s),
        ("omega (rad/s)", |t| t.omega_rad_s),
    ];
    for (k, (panel, (label, pick))) in panels.iter().zip(axes).enumerate() {
        let pts: Vec<(f64, f64, f64, bool)> = result
            .samples
            .iter()
            .filter_map(|s| {
                s.chassis.map(|c| {
                    (
                        s.t_ms as f64 * 1e-3,
                        f64::from(pick(&c.commanded)),
                        f64::from(pick(&c.achieved)),
                        c.link_lost,
                    )
                })
            })
            .collect();
        let (lo, hi) = pts
            .iter()
            .flat_map(|p| [p.1, p.2])
            .fold((0.0f64, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
        let pad = ((hi - lo) * 0.1).max(0.1);
        let mut builder = ChartBuilder::on(panel);
        builder
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(60);
        if k == 0 {
            builder.caption(
                format!("{} — commanded (dashed) and achieved twist", scenario.name),
                ("sans-serif", 18),
            );
        }
        let mut chart = builder
            .build_cartesian_2d(0.0..t_end, (lo - pad)..(hi + pad))
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_desc(label)
            .draw()
            .map_err(plot_err)?;
        // Shade the ticks where the remote link was lost.
        chart
            .draw_series(pts.iter().filter(|p| p.3).map(|p| {
                Rectangle::new(
                    [(p.0, lo - pad), (p.0 + 1e-3, hi + pad)],
                    RED.mix(0.08).filled(),
                )
            }))
            .map_err(plot_err)?;
        chart
            .draw_series(DashedLineSeries::new(
                pts.iter().map(|p| (p.0, p.1)),
                6,
                4,
                BLACK.stroke_width(1),
            ))
            .map_err(plot_err)?;
        chart
            .draw_series(LineSeries::new(
                pts.iter().map(|p| (p.0, p.2)),
                BLUE.stroke_width(2),
            ))
            .map_err(plot_err)?;
    }
    root.present().map_err(plot_err)
}

/// Writes `<name>.csv` and (unless `plots` is false) `<name>.svg` into `dir`; returns the paths.
pub fn write_all(
    scenario: &Scenario,
    result: &RunResult,
    dir: &Path,
    plots: bool,
) -> io::Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let csv = dir.join(format!("{}.csv", scenario.name));
    write_csv(result, &csv)?;
    let mut paths = vec![csv];
    if plots {
        let svg = dir.join(format!("{}.svg", scenario.name));
        write_svg(scenario, result, &svg)?;
        paths.push(svg);
        if scenario.chassis.is_some() {
            let twist = dir.join(format!("{}-twist.svg", scenario.name));
            write_chassis_svg(scenario, result, &twist)?;
            paths.push(twist);
        }
    }
    Ok(paths)
}
