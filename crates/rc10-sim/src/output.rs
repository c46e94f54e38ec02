//! Results for people: a metrics table for the terminal, per-tick traces as CSV, and plots of
//! target vs response and current as SVG (plotters; no system fonts needed).

use crate::scenario::{ChassisSample, RunResult, Scenario, TargetKind};
use plotters::prelude::*;
use rc10_core::chassis::Twist;
use std::fmt::Write as _;
use std::io;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// A time in seconds as ms with one decimal, or "never".
pub(crate) fn opt_ms(v: Option<f64>) -> String {
    v.map_or_else(|| "never".to_string(), |s| format!("{:.1} ms", s * 1e3))
}

/// A value rounded to a whole number, without a "-0".
fn whole(v: f64) -> String {
    let r = v.round();
    format!("{}", if r == 0.0 { 0.0 } else { r })
}

/// The unit of a target kind's values.
pub(crate) fn unit(kind: TargetKind) -> &'static str {
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
        "rc10      rx {} (unmatched {}, rejected {}), tx {} (dropped {}, still queued at a tick {} (frame-ticks)), offline events {:?}",
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
        "faults    frames lost {}, frames lost in full RX FIFOs {}, device TX drops {}",
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

/// Appends `v` with `decimals` (0 to 4) digits after the point, the same text as
/// `format!("{v:.decimals$}")` (an f32 widened to f64 prints the same), in a fraction of the
/// time: the standard formatter rounds the exact binary value with big-number arithmetic,
/// which made writing a trace cost four times the simulation it records.
///
/// Ordinary values (|v| < 1e9) are scaled by 10^decimals and rounded as an integer. A scaled
/// value that lands exactly on a half could be a true tie or a rounded near-tie; it, and
/// non-finite or huge values, go to the standard formatter.
fn push_fixed(out: &mut Vec<u8>, v: f64, decimals: usize) {
    const SCALE: [u64; 5] = [1, 10, 100, 1_000, 10_000];
    if let Some(&scale) = SCALE.get(decimals)
        && v.abs() < 1e9
    {
        let scaled = v.abs() * scale as f64;
        let whole = scaled as u64; // at most 1e13: truncation, exact
        let fraction = scaled - whole as f64; // exact
        // Rounding is monotone and every k + ½ below 2^52 is a float, so the rounded product
        // lies on the same side of k + ½ as the exact one, or exactly on it: only that case is
        // undecided here.
        if fraction != 0.5 {
            let n = whole + u64::from(fraction > 0.5);
            if v.is_sign_negative() {
                out.push(b'-');
            }
            push_digits(out, n / scale, 1);
            if decimals > 0 {
                out.push(b'.');
                push_digits(out, n % scale, decimals);
            }
            return;
        }
    }
    let _ = write!(out, "{v:.decimals$}");
}

/// Appends `n` in decimal, left-padded with zeros to at least `min_width` digits (at most 20):
/// what `write!(out, "{n:0min_width$}")` writes, without the formatting machinery.
fn push_digits(out: &mut Vec<u8>, mut n: u64, min_width: usize) {
    let mut digits = [b'0'; 20];
    let mut start = digits.len();
    while let Some(i) = start.checked_sub(1)
        && (n > 0 || digits.len() - start < min_width.max(1))
    {
        if let Some(d) = digits.get_mut(i) {
            *d = b'0' + (n % 10) as u8;
        }
        n /= 10;
        start = i;
    }
    out.extend_from_slice(digits.get(start..).unwrap_or_default());
}

/// Writes the per-tick trace as CSV: one row per ms, one column group per motor.
pub fn write_csv(result: &RunResult, path: &Path) -> io::Result<()> {
    let mut out = b"t_ms".to_vec();
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
        out.extend_from_slice(
            b",cmd_vx_m_s,cmd_vy_m_s,cmd_omega_rad_s,vx_m_s,vy_m_s,omega_rad_s,link_lost",
        );
    }
    out.push(b'\n');
    // Each motor's target as text, kept while it does not change (it rarely does).
    let mut targets: Vec<Option<(u32, Vec<u8>)>> = vec![None; n];
    for s in &result.samples {
        push_digits(&mut out, s.t_ms, 1);
        if targets.len() < s.motors.len() {
            targets.resize(s.motors.len(), None);
        }
        for (m, text) in s.motors.iter().zip(targets.iter_mut()) {
            let bits = m.target.to_bits();
            let text = match text {
                Some((b, t)) if *b == bits => t,
                _ => &mut text.insert((bits, format!(",{}", m.target).into_bytes())).1,
            };
            out.extend_from_slice(text);
            for v in [
                m.true_rpm,
                f64::from(m.measured_rpm),
                m.true_total_deg,
                f64::from(m.measured_total_deg),
                f64::from(m.command),
                m.current_amps,
            ] {
                out.push(b',');
                push_fixed(&mut out, v, 4);
            }
            out.push(b',');
            push_fixed(&mut out, m.temperature_c, 2);
            out.extend_from_slice(if m.online { b",1" } else { b",0" });
        }
        if let Some(c) = s.chassis {
            for v in [
                c.commanded.vx_m_s,
                c.commanded.vy_m_s,
                c.commanded.omega_rad_s,
                c.achieved.vx_m_s,
                c.achieved.vy_m_s,
                c.achieved.omega_rad_s,
            ] {
                out.push(b',');
                push_fixed(&mut out, f64::from(v), 4);
            }
            out.extend_from_slice(if c.link_lost { b",1" } else { b",0" });
        }
        out.push(b'\n');
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
    // Each motor in its own unit: degrees if its target is an angle, else rpm (a current
    // target is in amps: only the speed it gives is drawn).
    let kind_of = |i: usize| {
        scenario
            .targets
            .iter()
            .find(|t| t.motor == i)
            .map(|t| t.kind)
    };
    let is_angle = |i: usize| {
        matches!(
            kind_of(i),
            Some(TargetKind::AngleDeg | TargetKind::TotalAngleDeg)
        )
    };
    let angle_motors = (0..scenario.motors.len()).filter(|&i| is_angle(i)).count();
    let (angle, mixed) = (
        angle_motors > 0,
        angle_motors % scenario.motors.len().max(1) != 0,
    );
    let series: Vec<Vec<Point>> = (0..scenario.motors.len())
        .map(|i| {
            let response = |m: &crate::scenario::MotorSample| {
                if is_angle(i) {
                    m.true_total_deg
                } else {
                    m.true_rpm
                }
            };
            result
                .samples
                .iter()
                .filter_map(|s| {
                    s.motors.get(i).map(|m| {
                        let target = match kind_of(i) {
                            Some(TargetKind::AngleDeg) => {
                                // Show the angle target where the motor is headed.
                                let y = response(m);
                                y + f64::from(rc10_core::math::wrap_deg_180(m.target - y as f32))
                            }
                            Some(TargetKind::Current) => f64::NAN,
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
        .y_desc(if mixed {
            "output speed (rpm) or angle (deg), per motor"
        } else if angle {
            "output angle (deg)"
        } else {
            "output speed (rpm)"
        })
        .draw()
        .map_err(plot_err)?;
    for (i, (s, &color)) in series.iter().zip(COLORS.iter().cycle()).enumerate() {
        chart
            .draw_series(DashedLineSeries::new(
                s.iter()
                    .filter(|p| p.target.is_finite())
                    .map(|p| (p.t_s, p.target)),
                6,
                4,
                color.mix(0.6).stroke_width(1),
            ))
            .map_err(plot_err)?;
        let unit = match (mixed, is_angle(i)) {
            (false, _) => "",
            (true, true) => " (deg)",
            (true, false) => " (rpm)",
        };
        chart
            .draw_series(LineSeries::new(
                s.iter().map(|p| (p.t_s, p.response)),
                color.stroke_width(2),
            ))
            .map_err(plot_err)?
            .label(format!("motor {}{unit}", i + 1))
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

#[cfg(test)]
mod tests {
    use super::{push_digits, push_fixed, write_svg};
    use crate::scenario::run::uniform;
    use crate::scenario::{TargetKind, TargetSpec, builtin_named, run};
    use rand_xoshiro::Xoshiro256PlusPlus;
    use rand_xoshiro::rand_core::SeedableRng;

    /// Values around every edge the fast path must get right: exact ties (k/2^n), values a
    /// hair either side of a rounding point, signed zeros, tiny negatives that round to
    /// "-0.0000", the 1e9 limit, non-finite values, and a wide deterministic spread (f64 and
    /// f32 values).
    fn awkward_values() -> Vec<f64> {
        let mut v = crate::test_values::around_edges(
            &[
                0.0,
                -0.0,
                f64::NAN,
                f64::INFINITY,
                f64::NEG_INFINITY,
                1e-300,
                -1e-300,
            ],
            &[
                0.0,
                1.0,
                9.0,
                99.0,
                482.0,
                8191.0,
                16384.0,
                123_456.0,
                999_999_999.0,
                1e9,
            ],
            &[
                0.0, 0.5, 0.05, 0.005, 0.0005, 0.00005, 0.25, 0.125, 0.03125, 0.99995,
            ],
        );
        // Each of them as the nearest f32 too (values rc10 hands over as f32).
        let as_f32: Vec<f64> = v.iter().map(|x| f64::from(*x as f32)).collect();
        v.extend(as_f32);
        // Decimal near-ties: (k + ½)/10^d and its neighbours, whose scaled value often lands
        // exactly on the half.
        for d in [10.0, 100.0, 1e3, 1e4] {
            for k in 0..5_000 {
                let t = (f64::from(k) + 0.5) / d;
                v.extend([t, t.next_up(), t.next_down(), -t]);
            }
        }
        // Exact binary ties at each number of decimals: k/2^n for small n.
        for k in 0..2048 {
            v.extend([
                f64::from(k) / 1024.0,
                -f64::from(k) / 64.0,
                f64::from(k) / 32768.0,
            ]);
        }
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(1);
        for _ in 0..100_000 {
            let unit = uniform(&mut rng) - 0.5;
            v.extend([
                unit,
                unit * 1e3,
                unit * 2e5,
                unit * 2e9,
                f64::from((unit * 700.0) as f32),
            ]);
        }
        v
    }

    #[test]
    fn digits_match_the_standard_formatter() {
        let mut fast = Vec::new();
        for n in [
            0,
            1,
            9,
            10,
            99,
            100,
            4_321,
            10_000,
            599_999,
            u64::MAX - 1,
            u64::MAX,
        ] {
            for width in [1, 2, 4, 20] {
                fast.clear();
                push_digits(&mut fast, n, width);
                assert_eq!(fast, format!("{n:0width$}").as_bytes());
            }
        }
    }

    #[test]
    fn fixed_point_text_matches_the_standard_formatter() {
        let mut fast = Vec::new();
        for x in awkward_values() {
            for decimals in 0..=4 {
                fast.clear();
                push_fixed(&mut fast, x, decimals);
                let expected = format!("{x:.decimals$}");
                assert_eq!(fast, expected.as_bytes(), "{x:e} to {decimals} decimals");
            }
        }
        // An f32 prints as its f64 widening does (the trace widens its f32 columns).
        for x in [0.1f32, -2.675, 1.0e-5, 299.999_97, -0.0] {
            fast.clear();
            push_fixed(&mut fast, f64::from(x), 4);
            assert_eq!(fast, format!("{x:.4}").as_bytes());
        }
    }

    #[test]
    fn a_plot_of_angle_and_speed_motors_names_each_ones_unit() {
        let mut s = builtin_named("fault-power-cut").unwrap();
        s.faults.clear();
        s.duration_ms = 50;
        s.targets = vec![
            TargetSpec {
                motor: 0,
                kind: TargetKind::AngleDeg,
                steps: vec![(0, 90.0)],
            },
            TargetSpec {
                motor: 1,
                kind: TargetKind::Rpm,
                steps: vec![(0, 100.0)],
            },
        ];
        let r = run(&s).unwrap();
        let path = std::env::temp_dir().join(format!("rc10-mixed-{}.svg", std::process::id()));
        write_svg(&s, &r, &path).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert!(svg.contains("motor 1 (deg)"), "no degree label");
        assert!(svg.contains("motor 2 (rpm)"), "no rpm label");
        assert!(svg.contains("per motor"), "axis not marked as per motor");
    }
}
