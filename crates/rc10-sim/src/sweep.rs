//! Gain sweeps: a scenario run once for every combination of candidate gains of one motor's
//! speed or angle loop, on every core, each run ranked by how well the motor followed its
//! steps.
//!
//! Every run is the whole simulation (bus, plants, rc10's real drivers), deterministic: the
//! same scenario and gains give the same figures whatever the number of threads. A run
//! *qualifies* when each of the motor's steps settles within ±2 % of its size and overshoots
//! by at most the given percentage; qualifying runs rank first, each group by the sum of its
//! steps' integral of absolute error (IAE), the earlier combination first on a tie.
//!
//! ```
//! use rc10_sim::scenario::builtin_named;
//! use rc10_sim::sweep::{GainGrid, Loop, SweepSpec, sweep};
//! let scenario = builtin_named("m3508-speed-step").unwrap();
//! let spec = SweepSpec {
//!     motor: 0,
//!     tuned: Loop::Speed,
//!     grid: GainGrid { kp: vec![0.3, 0.6], ki: vec![8.0], kd: vec![] },
//!     max_overshoot_percent: 5.0,
//! };
//! let outcome = sweep(&scenario, &spec, 1, &|_| {}).unwrap();
//! assert_eq!(outcome.runs.len(), 2);
//! let best = outcome.ranked(5.0)[0];
//! assert!(best.qualifies(5.0));
//! ```

use crate::metrics::StepMetrics;
use crate::scenario::{Controller, Scenario, SimError, TargetKind, run};
use rc10_core::motor::dji::DjiConfig;
use rc10_core::pid::{PidConfig, PidConfigError};
use std::fmt;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Most runs one sweep makes (about 10 minutes of the default 400 ms step on one core of a
/// laptop).
pub const MAX_RUNS: usize = 100_000;

/// Which loop of the cascade a sweep tunes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Loop {
    /// The speed loop: rpm in, amps (volts for a GM6020 in voltage mode) out.
    Speed,
    /// The angle loop: degrees in, rpm out.
    Angle,
}

impl fmt::Display for Loop {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Loop::Speed => "speed",
            Loop::Angle => "angle",
        })
    }
}

/// Candidate gains, each in the loop's own units (speed loop: amps or volts per rpm, per
/// rpm·s, per rpm/s; angle loop: rpm per degree, per degree·s, per degree/s). An empty list
/// keeps the scenario's gain.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GainGrid {
    /// Proportional gains.
    pub kp: Vec<f32>,
    /// Integral gains, per second.
    pub ki: Vec<f32>,
    /// Derivative gains, times seconds.
    pub kd: Vec<f32>,
}

/// What to sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepSpec {
    /// The motor, an index into [`Scenario::motors`].
    pub motor: usize,
    /// The loop whose gains change.
    pub tuned: Loop,
    /// The candidates.
    pub grid: GainGrid,
    /// The largest overshoot, percent of the step, a run may have and qualify.
    pub max_overshoot_percent: f64,
}

/// One loop's three gains.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// Proportional gain.
    pub kp: f32,
    /// Integral gain, per second.
    pub ki: f32,
    /// Derivative gain, times seconds.
    pub kd: f32,
}

/// One run of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepRun {
    /// Its place in the grid (kp varies slowest, kd fastest).
    pub index: usize,
    /// The gains it ran with.
    pub gains: Gains,
    /// Step figures of each of the motor's speed and angle targets, in target order.
    pub steps: Vec<(TargetKind, StepMetrics)>,
}

impl SweepRun {
    /// Whether every step settled within ±2 % and overshot by at most
    /// `max_overshoot_percent`.
    pub fn qualifies(&self, max_overshoot_percent: f64) -> bool {
        !self.steps.is_empty()
            && self.steps.iter().all(|(_, m)| {
                m.settling_time_s.is_some() && m.overshoot_percent <= max_overshoot_percent
            })
    }

    /// The sum of the steps' IAE (rpm·s or degree·s): lower is better.
    pub fn iae(&self) -> f64 {
        self.steps.iter().map(|(_, m)| m.iae).sum()
    }
}

/// The runs of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepOutcome {
    /// The scenario's own gains, run as they are (index 0: it is not part of the grid).
    pub baseline: SweepRun,
    /// Every combination, in grid order.
    pub runs: Vec<SweepRun>,
}

impl SweepOutcome {
    /// The runs best first: those that qualify, by IAE, then the others, by IAE; on a tie
    /// the earlier in the grid.
    pub fn ranked(&self, max_overshoot_percent: f64) -> Vec<&SweepRun> {
        let mut runs: Vec<&SweepRun> = self.runs.iter().collect();
        runs.sort_by(|a, b| {
            let qa = a.qualifies(max_overshoot_percent);
            let qb = b.qualifies(max_overshoot_percent);
            qb.cmp(&qa)
                .then(a.iae().total_cmp(&b.iae()))
                .then(a.index.cmp(&b.index))
        });
        runs
    }
}

/// Why a sweep could not run.
#[derive(Debug, Clone, PartialEq)]
pub enum SweepError {
    /// The scenario has no motor of that index.
    NoMotor {
        /// The index asked for.
        motor: usize,
        /// How many motors the scenario has.
        motors: usize,
    },
    /// The motor runs RC10_LIB's comparison loop, whose gains are fixed.
    LegacyController,
    /// The motor has no speed or angle target with a step inside the run to measure.
    NoStep,
    /// More combinations than [`MAX_RUNS`].
    TooManyRuns {
        /// How many the lists make.
        runs: usize,
    },
    /// A candidate is not a valid gain.
    InvalidGains {
        /// The combination.
        gains: Gains,
        /// What is wrong with it.
        error: PidConfigError,
    },
    /// A run failed.
    Run(SimError),
}

impl fmt::Display for SweepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SweepError::NoMotor { motor, motors } => write!(
                f,
                "no motor {} (the scenario has {motors})",
                motor.saturating_add(1)
            ),
            SweepError::LegacyController => f.write_str(
                "the motor runs RC10_LIB's demo loop, whose gains are fixed: sweep an rc10 motor",
            ),
            SweepError::NoStep => f.write_str(
                "the motor has no speed or angle target with a step inside the run to measure \
                 (a chassis wheel's speed comes from the chassis)",
            ),
            SweepError::TooManyRuns { runs } => write!(
                f,
                "{runs} combinations: at most {MAX_RUNS} (fewer values per gain)"
            ),
            SweepError::InvalidGains { gains, error } => write!(
                f,
                "kp {} ki {} kd {}: {error}",
                gains.kp, gains.ki, gains.kd
            ),
            SweepError::Run(e) => write!(f, "{e}"),
        }
    }
}

impl std::error::Error for SweepError {}

/// Parses a list of candidate values: comma-separated numbers and `FROM:TO:COUNT` ranges
/// (`COUNT` evenly spaced values from `FROM` to `TO`, both included), e.g. `0.2:1.0:5,2`
/// (0.2, 0.4, 0.6, 0.8, 1.0, 2). Values must be finite.
pub fn parse_values(text: &str) -> Result<Vec<f32>, String> {
    let mut values = Vec::new();
    for item in text.split(',') {
        let item = item.trim();
        let number = |s: &str| -> Result<f32, String> {
            let v: f32 = s
                .trim()
                .parse()
                .map_err(|_| format!("`{s}` is not a number"))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(format!("`{s}` is not finite"))
            }
        };
        let parts: Vec<&str> = item.split(':').collect();
        match parts.as_slice() {
            [v] => values.push(number(v)?),
            [from, to, count] => {
                let (from, to) = (number(from)?, number(to)?);
                let count: usize = count
                    .trim()
                    .parse()
                    .ok()
                    .filter(|n| (1..=MAX_RUNS).contains(n))
                    .ok_or_else(|| {
                        format!("`{item}`: the count must be a whole number from 1 to {MAX_RUNS}")
                    })?;
                if count == 1 {
                    values.push(from);
                } else {
                    let step = (f64::from(to) - f64::from(from)) / (count - 1) as f64;
                    values.extend((0..count).map(|i| (f64::from(from) + step * i as f64) as f32));
                    // The last value is `to` itself, not `from` plus a rounded sum.
                    if let Some(last) = values.last_mut() {
                        *last = to;
                    }
                }
            }
            _ => {
                return Err(format!("`{item}` is neither a number nor FROM:TO:COUNT"));
            }
        }
    }
    Ok(values)
}

/// The loop configuration of `motor` in `scenario` (the controller's own, or the model's
/// shipped default).
fn base_config(scenario: &Scenario, motor: usize) -> Result<DjiConfig, SweepError> {
    let spec = scenario.motors.get(motor).ok_or(SweepError::NoMotor {
        motor,
        motors: scenario.motors.len(),
    })?;
    match spec.controller {
        Controller::Rc10 => Ok(DjiConfig::default_for(spec.model)),
        Controller::Rc10With(cfg) => Ok(cfg),
        Controller::Rc10Legacy => Err(SweepError::LegacyController),
    }
}

/// The loop a sweep of `motor` tunes when not told: the angle loop if the motor has an
/// angle target, else the speed loop.
pub fn default_loop(scenario: &Scenario, motor: usize) -> Loop {
    let angle = scenario.targets.iter().any(|t| {
        t.motor == motor && matches!(t.kind, TargetKind::AngleDeg | TargetKind::TotalAngleDeg)
    });
    if angle { Loop::Angle } else { Loop::Speed }
}

/// Runs `scenario` once with its own gains and once for every combination of `spec.grid`,
/// on `jobs` threads (at least one), calling `progress` with the number of runs done after
/// each. The scenario's other motors and everything else stay as they are.
pub fn sweep(
    scenario: &Scenario,
    spec: &SweepSpec,
    jobs: usize,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SweepOutcome, SweepError> {
    let base = base_config(scenario, spec.motor)?;
    let measured = scenario
        .targets
        .iter()
        .any(|t| t.motor == spec.motor && t.kind != TargetKind::Current && !t.steps.is_empty());
    if !measured {
        return Err(SweepError::NoStep);
    }
    let loop_config = |cfg: &DjiConfig| match spec.tuned {
        Loop::Speed => cfg.cascade.speed,
        Loop::Angle => cfg.cascade.angle,
    };
    let own = loop_config(&base);
    let or_own = |list: &[f32], own: f32| {
        if list.is_empty() {
            vec![own]
        } else {
            list.to_vec()
        }
    };
    let (kps, kis, kds) = (
        or_own(&spec.grid.kp, own.kp),
        or_own(&spec.grid.ki, own.ki),
        or_own(&spec.grid.kd, own.kd),
    );
    let count = kps
        .len()
        .checked_mul(kis.len())
        .and_then(|n| n.checked_mul(kds.len()))
        .unwrap_or(usize::MAX);
    if count > MAX_RUNS {
        return Err(SweepError::TooManyRuns { runs: count });
    }
    let mut grid = Vec::with_capacity(count);
    for &kp in &kps {
        for &ki in &kis {
            for &kd in &kds {
                let gains = Gains { kp, ki, kd };
                let pid = PidConfig { kp, ki, kd, ..own };
                pid.validate()
                    .map_err(|error| SweepError::InvalidGains { gains, error })?;
                let mut cfg = base;
                match spec.tuned {
                    Loop::Speed => cfg.cascade.speed = pid,
                    Loop::Angle => cfg.cascade.angle = pid,
                }
                grid.push((gains, cfg));
            }
        }
    }

    let one = |index: usize, gains: Gains, cfg: Option<DjiConfig>| {
        let mut s = scenario.clone();
        if let (Some(cfg), Some(m)) = (cfg, s.motors.get_mut(spec.motor)) {
            m.controller = Controller::Rc10With(cfg);
        }
        run(&s).map(|r| SweepRun {
            index,
            gains,
            steps: r
                .metrics
                .iter()
                .filter(|m| m.motor == spec.motor)
                .map(|m| (m.kind, m.metrics))
                .collect(),
        })
    };
    let baseline = one(
        0,
        Gains {
            kp: own.kp,
            ki: own.ki,
            kd: own.kd,
        },
        None,
    )
    .map_err(SweepError::Run)?;
    // Every run has the same steps at the same times: none measured here (a step after the
    // end of the run), none anywhere.
    if baseline.steps.is_empty() {
        return Err(SweepError::NoStep);
    }

    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let mut results: Vec<(usize, Result<SweepRun, SimError>)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..jobs.clamp(1, count.max(1)))
            .map(|_| {
                scope.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let index = next.fetch_add(1, Ordering::Relaxed);
                        let Some(&(gains, cfg)) = grid.get(index) else {
                            break;
                        };
                        mine.push((index, one(index, gains, Some(cfg))));
                        progress(done.fetch_add(1, Ordering::Relaxed).saturating_add(1));
                    }
                    mine
                })
            })
            .collect();
        workers
            .into_iter()
            .flat_map(|w| match w.join() {
                Ok(mine) => mine,
                // A run that panicked takes the sweep down with it, as it would alone.
                Err(panic) => std::panic::resume_unwind(panic),
            })
            .collect()
    });
    results.sort_by_key(|(index, _)| *index);
    let runs = results
        .into_iter()
        .map(|(_, r)| r)
        .collect::<Result<Vec<_>, _>>()
        .map_err(SweepError::Run)?;
    Ok(SweepOutcome { baseline, runs })
}

/// The figures a table row shows for a run: the worst of its steps' (the longest rise and
/// settling, the largest overshoot, steady error and current) and the sum of their IAE.
struct Row {
    rise_s: Option<f64>,
    overshoot_percent: f64,
    settling_s: Option<f64>,
    steady_error: f64,
    iae: f64,
    peak_amps: f64,
}

impl Row {
    fn of(run: &SweepRun) -> Row {
        let worst = |f: fn(&StepMetrics) -> Option<f64>| {
            run.steps
                .iter()
                .map(|(_, m)| f(m))
                .try_fold(0.0f64, |acc, v| v.map(|v| acc.max(v)))
        };
        let largest =
            |f: fn(&StepMetrics) -> f64| run.steps.iter().map(|(_, m)| f(m)).fold(0.0f64, f64::max);
        Row {
            rise_s: worst(|m| m.rise_time_s),
            overshoot_percent: largest(|m| m.overshoot_percent),
            settling_s: worst(|m| m.settling_time_s),
            steady_error: largest(|m| m.steady_state_error),
            iae: run.iae(),
            peak_amps: largest(|m| m.peak_current_amps),
        }
    }
}

/// A gain with five significant digits at most, without trailing zeros (the CSV has every
/// digit).
fn gain(v: f32) -> String {
    let magnitude = if v == 0.0 {
        0
    } else {
        f64::from(v).abs().log10().floor() as i32
    };
    let decimals = usize::try_from((4 - magnitude).clamp(0, 12)).unwrap_or(0);
    let text = format!("{v:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

fn ms(v: Option<f64>) -> String {
    v.map_or_else(|| "never".to_string(), |s| format!("{:.1} ms", s * 1e3))
}

/// The unit of the steps' error (rpm or deg), from the first step.
fn error_unit(outcome: &SweepOutcome) -> &'static str {
    match outcome.baseline.steps.first().map(|(k, _)| *k) {
        Some(TargetKind::Rpm) | None => "rpm",
        Some(TargetKind::Current) => "A",
        Some(TargetKind::AngleDeg | TargetKind::TotalAngleDeg) => "deg",
    }
}

/// The scenario's own gains, then the best `top` runs, as a table; figures are the worst of
/// the motor's steps, IAE their sum.
pub fn table(outcome: &SweepOutcome, max_overshoot_percent: f64, top: usize) -> String {
    use fmt::Write as _;
    let u = error_unit(outcome);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<9} {:>9} {:>9} {:>9} {:>10} {:>10} {:>10} {:>14} {:>13} {:>9}  qualifies",
        "rank", "kp", "ki", "kd", "rise", "overshoot", "settle 2%", "steady err", "IAE", "peak I",
    );
    let mut line = |rank: String, run: &SweepRun| {
        let r = Row::of(run);
        let _ = writeln!(
            s,
            "{rank:<9} {:>9} {:>9} {:>9} {:>10} {:>9.2}% {:>10} {:>10.3} {u:<3} {:>13} {:>7.2} A  {}",
            gain(run.gains.kp),
            gain(run.gains.ki),
            gain(run.gains.kd),
            ms(r.rise_s),
            r.overshoot_percent,
            ms(r.settling_s),
            r.steady_error,
            format!("{:.3} {u}·s", r.iae),
            r.peak_amps,
            if run.qualifies(max_overshoot_percent) {
                "yes"
            } else {
                "no"
            }
        );
    };
    line("scenario".to_string(), &outcome.baseline);
    for (i, run) in outcome
        .ranked(max_overshoot_percent)
        .into_iter()
        .take(top)
        .enumerate()
    {
        line(format!("{}", i.saturating_add(1)), run);
    }
    s
}

/// Writes every run, in grid order, as CSV: the gains, whether it qualifies, the IAE sum,
/// then each step's figures (rise and settling in ms, empty when never reached).
pub fn write_csv(
    outcome: &SweepOutcome,
    max_overshoot_percent: f64,
    path: &std::path::Path,
) -> std::io::Result<()> {
    use std::io::Write as _;
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    let u = error_unit(outcome);
    write!(out, "index,kp,ki,kd,qualifies,iae_{u}_s")?;
    for i in 1..=outcome.baseline.steps.len() {
        write!(
            out,
            ",step{i}_rise_ms,step{i}_overshoot_percent,step{i}_settling_ms,\
             step{i}_steady_error_{u},step{i}_peak_amps"
        )?;
    }
    writeln!(out)?;
    let opt = |v: Option<f64>| v.map_or_else(String::new, |s| format!("{:.3}", s * 1e3));
    for run in &outcome.runs {
        write!(
            out,
            "{},{},{},{},{},{}",
            run.index,
            run.gains.kp,
            run.gains.ki,
            run.gains.kd,
            u8::from(run.qualifies(max_overshoot_percent)),
            run.iae()
        )?;
        for (_, m) in &run.steps {
            write!(
                out,
                ",{},{},{},{},{}",
                opt(m.rise_time_s),
                m.overshoot_percent,
                opt(m.settling_time_s),
                m.steady_state_error,
                m.peak_current_amps
            )?;
        }
        writeln!(out)?;
    }
    out.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::min_speed_rise_time_s;
    use crate::plant::MotorParams;
    use crate::scenario::builtin_named;

    fn scenario(name: &str) -> Scenario {
        builtin_named(name).unwrap_or_else(|| panic!("no scenario {name}"))
    }

    fn speed_spec(grid: GainGrid) -> SweepSpec {
        SweepSpec {
            motor: 0,
            tuned: Loop::Speed,
            grid,
            max_overshoot_percent: 5.0,
        }
    }

    #[test]
    fn table_gains_keep_five_significant_digits() {
        for (v, text) in [
            (0.0, "0"),
            (0.6, "0.6"),
            (8.0, "8"),
            (1.017_241_4, "1.0172"),
            (-0.000_123_45, "-0.00012345"),
            (12_345.6, "12346"),
            (250.0, "250"),
        ] {
            assert_eq!(gain(v), text, "{v}");
        }
    }

    #[test]
    fn value_lists_take_numbers_and_inclusive_ranges() {
        assert_eq!(parse_values("0.5").unwrap(), vec![0.5]);
        assert_eq!(parse_values("1, 2,3").unwrap(), vec![1.0, 2.0, 3.0]);
        assert_eq!(
            parse_values("0:1:5,7").unwrap(),
            vec![0.0, 0.25, 0.5, 0.75, 1.0, 7.0]
        );
        // Both ends exactly, however the step rounds.
        let v = parse_values("0.1:0.7:7").unwrap();
        assert_eq!((v.len(), v[0], v[6]), (7, 0.1, 0.7));
        assert_eq!(parse_values("3:9:1").unwrap(), vec![3.0]);
        assert_eq!(parse_values("2:1:3").unwrap(), vec![2.0, 1.5, 1.0]);
        for bad in [
            "", "x", "1:2", "1:2:0", "1:2:x", "1:2:3:4", "nan", "inf", "1,,2",
        ] {
            assert!(parse_values(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn the_grid_runs_every_combination_in_order_with_the_scenario_gains_kept_where_unswept() {
        let spec = speed_spec(GainGrid {
            kp: vec![0.4, 0.6],
            ki: vec![4.0, 8.0, 12.0],
            kd: vec![],
        });
        let out = sweep(&scenario("m3508-speed-step"), &spec, 2, &|_| {}).unwrap();
        let gains: Vec<(f32, f32, f32)> = out
            .runs
            .iter()
            .map(|r| (r.gains.kp, r.gains.ki, r.gains.kd))
            .collect();
        assert_eq!(
            gains,
            [
                (0.4, 4.0, 0.0),
                (0.4, 8.0, 0.0),
                (0.4, 12.0, 0.0),
                (0.6, 4.0, 0.0),
                (0.6, 8.0, 0.0),
                (0.6, 12.0, 0.0)
            ]
        );
        assert!(out.runs.iter().enumerate().all(|(i, r)| r.index == i));
        // The shipped M3508 speed loop is kp 0.6, ki 8: the baseline, and the grid's run of the
        // same gains gives the same figures (the same simulation).
        assert_eq!((out.baseline.gains.kp, out.baseline.gains.ki), (0.6, 8.0));
        assert_eq!(out.runs[4].steps, out.baseline.steps);
        assert_eq!(out.baseline.steps.len(), 1);
    }

    #[test]
    fn threads_do_not_change_the_figures() {
        let spec = speed_spec(GainGrid {
            kp: vec![0.2, 0.6, 1.2],
            ki: vec![2.0, 8.0],
            kd: vec![],
        });
        let s = scenario("m2006-speed-step");
        let one = sweep(&s, &spec, 1, &|_| {}).unwrap();
        let two = sweep(&s, &spec, 2, &|_| {}).unwrap();
        let many = sweep(&s, &spec, 64, &|_| {}).unwrap();
        assert_eq!(one, two);
        assert_eq!(one, many);
    }

    #[test]
    fn a_loop_too_weak_to_use_the_current_ranks_below_the_shipped_gains() {
        // kp 0.01 A/rpm asks for 3 A at the 300 rpm step, a sixth of the 20 A the C620 can
        // give: the rise takes several times the full-current minimum, and the integral
        // (ki 0.1 A per rpm·s) cannot make that up within the 400 ms run.
        let spec = speed_spec(GainGrid {
            kp: vec![0.01, 0.6],
            ki: vec![0.1, 8.0],
            kd: vec![],
        });
        let s = scenario("m3508-speed-step");
        let out = sweep(&s, &spec, 2, &|_| {}).unwrap();
        let ranked = out.ranked(5.0);
        let best = ranked[0];
        assert_eq!((best.gains.kp, best.gains.ki), (0.6, 8.0));
        let weakest = &out.runs[0];
        assert_eq!((weakest.gains.kp, weakest.gains.ki), (0.01, 0.1));
        assert!(!weakest.qualifies(5.0));
        assert_eq!(ranked.last().map(|r| r.index), Some(0));
        let min = min_speed_rise_time_s(
            MotorParams::for_model(s.motors[0].model),
            s.motors[0].load,
            300.0,
        )
        .unwrap();
        let (_, m) = weakest.steps[0];
        assert!(m.rise_time_s.is_none_or(|r| r > 3.0 * min), "{m:?}");
        // Ranked by IAE among the qualified: the weak run's error lasts the whole window.
        assert!(weakest.iae() > 2.0 * best.iae());
    }

    fn synthetic(index: usize, overshoot_percent: f64, settles: bool, iae: f64) -> SweepRun {
        SweepRun {
            index,
            gains: Gains {
                kp: index as f32,
                ki: 0.0,
                kd: 0.0,
            },
            steps: vec![(
                TargetKind::Rpm,
                StepMetrics {
                    initial: 0.0,
                    target: 100.0,
                    rise_time_s: Some(0.01),
                    overshoot_percent,
                    settling_time_s: settles.then_some(0.05),
                    steady_state_error: 0.0,
                    iae,
                    peak_current_amps: 1.0,
                },
            )],
        }
    }

    #[test]
    fn qualifying_runs_rank_first_each_group_by_error_then_grid_order() {
        let runs = vec![
            synthetic(0, 9.0, true, 1.0), // overshoots: out, however small its error
            synthetic(1, 1.0, true, 3.0), // in
            synthetic(2, 0.0, false, 0.5), // never settles: out
            synthetic(3, 5.0, true, 2.0), // in: at the limit counts
            synthetic(4, 2.0, true, 2.0), // in, the same error as 3: after it
            synthetic(5, 9.0, true, 4.0), // out
        ];
        let outcome = SweepOutcome {
            baseline: synthetic(0, 0.0, true, 1.0),
            runs,
        };
        let order: Vec<usize> = outcome.ranked(5.0).iter().map(|r| r.index).collect();
        assert_eq!(order, [3, 4, 1, 2, 0, 5]);
        // With no limit to speak of, only settling counts.
        let order: Vec<usize> = outcome.ranked(100.0).iter().map(|r| r.index).collect();
        assert_eq!(order, [0, 3, 4, 1, 5, 2]);
        // Nothing measured qualifies for nothing.
        let unmeasured = SweepRun {
            steps: Vec::new(),
            ..synthetic(6, 0.0, true, 0.0)
        };
        assert!(!unmeasured.qualifies(100.0));
    }

    #[test]
    fn a_stiffer_integral_overshoots_more_and_drops_out_under_a_tight_limit() {
        // PI on the motor's first-order speed response: raising ki against the same kp lowers
        // the closed loop's damping, so the speed swings further past the step once the
        // current leaves its limit.
        let spec = speed_spec(GainGrid {
            kp: vec![0.6],
            ki: vec![8.0, 120.0],
            kd: vec![],
        });
        let out = sweep(&scenario("m3508-speed-step"), &spec, 1, &|_| {}).unwrap();
        let (_, soft) = out.runs[0].steps[0];
        let (_, stiff) = out.runs[1].steps[0];
        assert!(
            stiff.overshoot_percent > 1.0 && stiff.overshoot_percent > 2.0 * soft.overshoot_percent,
            "{soft:?} {stiff:?}"
        );
        let limit = (soft.overshoot_percent + stiff.overshoot_percent) / 2.0;
        assert!(out.runs[0].qualifies(limit));
        assert!(!out.runs[1].qualifies(limit));
        assert_eq!(out.ranked(limit)[0].index, 0);
    }

    #[test]
    fn an_angle_sweep_tunes_the_angle_loop() {
        let s = scenario("m3508-angle-step");
        assert_eq!(default_loop(&s, 0), Loop::Angle);
        let spec = SweepSpec {
            motor: 0,
            tuned: Loop::Angle,
            grid: GainGrid {
                kp: vec![1.0, 8.0],
                ..GainGrid::default()
            },
            max_overshoot_percent: 5.0,
        };
        let out = sweep(&s, &spec, 2, &|_| {}).unwrap();
        // The shipped angle loop is kp 8 rpm/deg: the grid's second run is the baseline.
        assert_eq!(out.runs[1].steps, out.baseline.steps);
        // 1 rpm per degree of error (6°/s per degree) closes the 10° step with a time constant
        // of 1/6 s; 8 rpm per degree in 21 ms, less the time to accelerate.
        let (kind, slow) = out.runs[0].steps[0];
        let (_, fast) = out.runs[1].steps[0];
        assert_eq!(kind, TargetKind::AngleDeg);
        assert!(slow.iae > 3.0 * fast.iae, "{slow:?} {fast:?}");
    }

    #[test]
    fn refused_sweeps_say_why() {
        let s = scenario("m3508-speed-step");
        let grid = GainGrid {
            kp: vec![0.5],
            ..GainGrid::default()
        };
        let with_motor = |motor| SweepSpec {
            motor,
            ..speed_spec(grid.clone())
        };
        assert_eq!(
            sweep(&s, &with_motor(1), 1, &|_| {}),
            Err(SweepError::NoMotor {
                motor: 1,
                motors: 1
            })
        );
        assert_eq!(
            sweep(
                &scenario("m3508-speed-step-rc10lib"),
                &with_motor(0),
                1,
                &|_| {}
            ),
            Err(SweepError::LegacyController)
        );
        assert_eq!(
            sweep(
                &scenario("chassis-remote-drive"),
                &with_motor(0),
                1,
                &|_| {}
            ),
            Err(SweepError::NoStep)
        );
        // A step after the end of the run: nothing to rank by.
        let mut late = s.clone();
        late.targets[0].steps = vec![(late.duration_ms + 100, 300.0)];
        assert_eq!(
            sweep(&late, &with_motor(0), 1, &|_| {}),
            Err(SweepError::NoStep)
        );
        // Through the library (the command line's lists refuse it): a gain that is not finite.
        let infinite = speed_spec(GainGrid {
            kp: vec![0.5, f32::INFINITY],
            ..GainGrid::default()
        });
        assert!(matches!(
            sweep(&s, &infinite, 1, &|_| {}),
            Err(SweepError::InvalidGains { gains, error: PidConfigError::GainNotFinite })
                if gains.kp == f32::INFINITY
        ));
        let huge = speed_spec(GainGrid {
            kp: vec![1.0; 1000],
            ki: vec![1.0; 1000],
            kd: vec![],
        });
        assert_eq!(
            sweep(&s, &huge, 1, &|_| {}),
            Err(SweepError::TooManyRuns { runs: 1_000_000 })
        );
    }

    #[test]
    fn progress_counts_every_run() {
        let calls = AtomicUsize::new(0);
        let highest = AtomicUsize::new(0);
        let spec = speed_spec(GainGrid {
            kp: vec![0.4, 0.5, 0.6],
            ..GainGrid::default()
        });
        sweep(&scenario("m3508-speed-step"), &spec, 2, &|n| {
            calls.fetch_add(1, Ordering::Relaxed);
            highest.fetch_max(n, Ordering::Relaxed);
        })
        .unwrap();
        assert_eq!(calls.load(Ordering::Relaxed), 3);
        assert_eq!(highest.load(Ordering::Relaxed), 3);
    }
}
