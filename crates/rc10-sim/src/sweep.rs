//! Gain sweeps: a scenario run once (or once per seed) for every combination of candidate
//! gains of one motor's speed or angle loop, on every core, each combination ranked by how
//! well the motor followed its steps.
//!
//! Every run is the whole simulation (bus, plants, rc10's real drivers), deterministic: the
//! same scenario and gains give the same figures whatever the number of threads. Each speed
//! or angle step of the motor's target profiles ([`motor_step_windows`]: the same steps in
//! every run) is measured on the physical signal until the motor's next change of target (or
//! the end of the run). A run *qualifies* when every step settles within ±2 % of its size
//! before the last tenth of its window and overshoots by at most the given percentage;
//! qualifying runs rank first, each group by the sum of the steps' integral of absolute error
//! (IAE), the earlier combination first on a tie.
//!
//! IAE weighs error only: a loop that chatters (a large kd, say) costs current and heat that
//! the ranking does not see; the peak current is shown beside it. A run uses the scenario's
//! seed (ESC phases, random faults), and gains that win by a hair under one seed may not win
//! under another: [`SweepSpec::seeds`] runs each combination under several and keeps the
//! worst figures of each step.
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
//!     seeds: 1,
//! };
//! let outcome = sweep(&scenario, &spec, 1, &|_| {}).unwrap();
//! assert_eq!(outcome.runs.len(), 2);
//! let best = outcome.ranked(5.0)[0];
//! assert!(best.qualifies(5.0));
//! ```

use crate::scenario::{
    Controller, MeasuredStep, Scenario, SimError, StepWindow, TargetKind, measure_step,
    motor_step_windows, run,
};
use rc10_core::motor::dji::DjiConfig;
use rc10_core::pid::{PidConfig, PidConfigError};
use std::fmt;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Most runs one sweep makes, and most values one list gives (100,000 runs of the 400 ms
/// M3508 step take about 25 s on one thread of the machine in BENCHMARKS.md).
pub const MAX_RUNS: usize = 100_000;

/// Most threads a sweep starts, whatever it is asked for.
pub const MAX_JOBS: usize = 256;

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

/// Candidate gains in the loop's own units. Speed loop: kp in A/rpm (V/rpm for a GM6020 in
/// voltage mode), ki in A/(rpm·s), kd in A/(rpm/s). Angle loop: kp in rpm/deg, ki in
/// rpm/(deg·s), kd in rpm/(deg/s). An empty list keeps the scenario's gain.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GainGrid {
    /// Proportional gains.
    pub kp: Vec<f32>,
    /// Integral gains.
    pub ki: Vec<f32>,
    /// Derivative gains.
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
    /// How many seeds each combination runs with: the scenario's and the `seeds − 1` after
    /// it (ESC feedback phases, random faults). Each figure of each step is the worst of them
    /// on its own (the longest rise and settling, the largest overshoot, error, IAE and
    /// current; one row can mix seeds), its start and target the first seed's: gains that
    /// rank well hold up under every seed. At least 1.
    pub seeds: u32,
}

/// One loop's three gains, in the units of [`GainGrid`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// Proportional gain.
    pub kp: f32,
    /// Integral gain.
    pub ki: f32,
    /// Derivative gain.
    pub kd: f32,
}

/// One combination of a sweep: its run's figures, or with several seeds the worst of its
/// runs'.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepRun {
    /// Its place in the grid (kp varies slowest, kd fastest); `None` for the scenario's own
    /// gains.
    pub index: Option<usize>,
    /// The gains it ran with.
    pub gains: Gains,
    /// Every speed and angle step of the motor, in time order (the same steps in every run).
    pub steps: Vec<MeasuredStep>,
}

impl SweepRun {
    /// Whether it has steps and every one settled within ±2 % before the last tenth of its
    /// window and overshot by at most `max_overshoot_percent`.
    pub fn qualifies(&self, max_overshoot_percent: f64) -> bool {
        !self.steps.is_empty()
            && self.steps.iter().all(|s| {
                // In whole ms (samples come every ms): settled at 360 ms of a 400 ms window
                // is in time, whatever the rounding of the seconds.
                let settled_in_time = s.metrics.settling_time_s.is_some_and(|t| {
                    let settled_ms = (t * 1e3).round();
                    settled_ms >= 0.0 && settled_ms * 10.0 <= 9.0 * s.window_ms as f64
                });
                settled_in_time && s.metrics.overshoot_percent <= max_overshoot_percent
            })
    }

    /// The sum of the steps' IAE (rpm·s or deg·s): lower is better.
    pub fn iae(&self) -> f64 {
        self.steps.iter().map(|s| s.metrics.iae).sum()
    }
}

/// Best first: qualifying, then by IAE.
fn better(a: &SweepRun, b: &SweepRun, max_overshoot_percent: f64) -> std::cmp::Ordering {
    let qa = a.qualifies(max_overshoot_percent);
    let qb = b.qualifies(max_overshoot_percent);
    qb.cmp(&qa).then(a.iae().total_cmp(&b.iae()))
}

/// The runs of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepOutcome {
    /// The scenario's own gains, run as they are (not part of the grid).
    pub baseline: SweepRun,
    /// Every combination, in grid order.
    pub runs: Vec<SweepRun>,
}

impl SweepOutcome {
    /// The runs best first: those that qualify, by IAE, then the others, by IAE; on a tie
    /// the earlier in the grid.
    pub fn ranked(&self, max_overshoot_percent: f64) -> Vec<&SweepRun> {
        let mut runs: Vec<&SweepRun> = self.runs.iter().collect();
        runs.sort_by(|a, b| better(a, b, max_overshoot_percent).then(a.index.cmp(&b.index)));
        runs
    }

    /// Where the scenario's own gains would rank among the runs (1 = best; after the runs
    /// they tie with).
    pub fn baseline_rank(&self, max_overshoot_percent: f64) -> usize {
        let ahead = self
            .runs
            .iter()
            .filter(|r| better(r, &self.baseline, max_overshoot_percent).is_le())
            .count();
        ahead.saturating_add(1)
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
    /// The motor has no speed or angle step inside the run to measure (see
    /// [`motor_step_windows`]).
    NoStep,
    /// The motor's steps mix speeds and angles, whose errors do not add up.
    MixedSteps,
    /// The angle loop was asked for, and the motor has no angle target: it never runs.
    AngleLoopUnused,
    /// No list of candidates: the sweep would be the scenario's own run.
    NothingToSweep,
    /// Zero seeds: nothing would run.
    NoSeeds,
    /// More runs (combinations times seeds) than [`MAX_RUNS`].
    TooManyRuns {
        /// How many the lists and seeds make (saturated).
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
                "the motor has no speed or angle step inside the run to measure (a chassis \
                 wheel's speed comes from the chassis)",
            ),
            SweepError::MixedSteps => f.write_str(
                "the motor's steps mix speeds and angles: sweep a scenario with one kind",
            ),
            SweepError::AngleLoopUnused => f.write_str(
                "the motor has no angle target, so its angle loop never runs: sweep the speed loop",
            ),
            SweepError::NothingToSweep => {
                f.write_str("no candidate gains: give at least one list (kp, ki or kd)")
            }
            SweepError::NoSeeds => f.write_str("at least one seed"),
            SweepError::TooManyRuns { runs } => write!(
                f,
                "{runs} runs: at most {MAX_RUNS} (fewer values per gain, or fewer seeds)"
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

/// Why a list of candidate values was refused.
#[derive(Debug, Clone, PartialEq)]
pub enum ValueListError {
    /// An item is not a number.
    NotANumber(String),
    /// A number is infinite or NaN.
    NotFinite(String),
    /// A range's count is not a whole number from 2 to [`MAX_RUNS`].
    BadCount(String),
    /// An item is neither a number nor `FROM:TO:COUNT`.
    BadForm(String),
    /// A value comes twice (its runs would be the same).
    Repeated(f32),
    /// More than [`MAX_RUNS`] values.
    TooMany,
}

impl fmt::Display for ValueListError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ValueListError::NotANumber(s) => write!(f, "`{s}` is not a number"),
            ValueListError::NotFinite(s) => write!(f, "`{s}` is not finite"),
            ValueListError::BadCount(s) => write!(
                f,
                "`{s}`: the count must be a whole number from 2 to {MAX_RUNS} (one value: write \
                 the number)"
            ),
            ValueListError::BadForm(s) => {
                write!(f, "`{s}` is neither a number nor FROM:TO:COUNT")
            }
            ValueListError::Repeated(v) => write!(f, "{v} comes twice"),
            ValueListError::TooMany => write!(f, "more than {MAX_RUNS} values"),
        }
    }
}

impl std::error::Error for ValueListError {}

/// Parses a list of candidate values: comma-separated numbers and `FROM:TO:COUNT` ranges
/// (`COUNT` ≥ 2 evenly spaced values from `FROM` to `TO`, both included), e.g. `0.2:1.0:5,2`
/// (0.2, 0.4, 0.6, 0.8, 1.0, 2). Values must be finite and each come once (`0:0:3` and
/// `1,1` are refused); at most [`MAX_RUNS`] in all.
pub fn parse_values(text: &str) -> Result<Vec<f32>, ValueListError> {
    let number = |s: &str| -> Result<f32, ValueListError> {
        let v: f32 = s
            .trim()
            .parse()
            .map_err(|_| ValueListError::NotANumber(s.trim().to_string()))?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(ValueListError::NotFinite(s.trim().to_string()))
        }
    };
    let mut values: Vec<f32> = Vec::new();
    for item in text.split(',') {
        let item = item.trim();
        let parts: Vec<&str> = item.split(':').collect();
        match parts.as_slice() {
            [v] => values.push(number(v)?),
            [from, to, count] => {
                let (from, to) = (number(from)?, number(to)?);
                let count: usize = count
                    .trim()
                    .parse()
                    .ok()
                    .filter(|n| (2..=MAX_RUNS).contains(n))
                    .ok_or_else(|| ValueListError::BadCount(item.to_string()))?;
                if count > MAX_RUNS.saturating_sub(values.len()) {
                    return Err(ValueListError::TooMany);
                }
                let step = (f64::from(to) - f64::from(from)) / (count - 1) as f64;
                values.extend((0..count).map(|i| (f64::from(from) + step * i as f64) as f32));
                // The last value is `to` itself, not `from` plus a rounded sum.
                if let Some(last) = values.last_mut() {
                    *last = to;
                }
            }
            _ => return Err(ValueListError::BadForm(item.to_string())),
        }
        if values.len() > MAX_RUNS {
            return Err(ValueListError::TooMany);
        }
    }
    // Repeats, found in a sorted copy (the list keeps the user's order).
    let mut sorted = values.clone();
    sorted.sort_by(f32::total_cmp);
    if let Some(pair) = sorted.windows(2).find(|pair| pair.first() == pair.get(1)) {
        return Err(ValueListError::Repeated(
            pair.first().copied().unwrap_or(0.0),
        ));
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

fn is_angle(kind: TargetKind) -> bool {
    matches!(kind, TargetKind::AngleDeg | TargetKind::TotalAngleDeg)
}

/// The motor a sweep tunes when not told: the lowest-numbered rc10 motor with a speed or
/// angle step inside the run ([`motor_step_windows`]), if any.
pub fn default_motor(scenario: &Scenario) -> Option<usize> {
    (0..scenario.motors.len()).find(|&motor| {
        scenario
            .motors
            .get(motor)
            .is_some_and(|m| m.controller != Controller::Rc10Legacy)
            && !motor_step_windows(&scenario.targets, motor, scenario.duration_ms).is_empty()
    })
}

/// The loop a sweep of `motor` tunes when not told: the angle loop if the motor has an
/// angle step inside the run, else the speed loop.
pub fn default_loop(scenario: &Scenario, motor: usize) -> Loop {
    let windows = motor_step_windows(&scenario.targets, motor, scenario.duration_ms);
    if windows.iter().any(|w| is_angle(w.kind)) {
        Loop::Angle
    } else {
        Loop::Speed
    }
}

/// The worse of two seeds' figures of one step, figure by figure (`a`'s start and target):
/// the longer rise and settling (none if either has none), the larger overshoot, steady
/// error, IAE and current (NaN if either is NaN).
fn worse(a: &MeasuredStep, b: &MeasuredStep) -> MeasuredStep {
    let larger = |x: f64, y: f64| {
        if x.is_nan() || y.is_nan() {
            f64::NAN
        } else {
            x.max(y)
        }
    };
    let later = |x: Option<f64>, y: Option<f64>| Some(larger(x?, y?));
    let (m, n) = (&a.metrics, &b.metrics);
    MeasuredStep {
        metrics: crate::metrics::StepMetrics {
            rise_time_s: later(m.rise_time_s, n.rise_time_s),
            overshoot_percent: larger(m.overshoot_percent, n.overshoot_percent),
            settling_time_s: later(m.settling_time_s, n.settling_time_s),
            steady_state_error: larger(m.steady_state_error, n.steady_state_error),
            iae: larger(m.iae, n.iae),
            peak_current_amps: larger(m.peak_current_amps, n.peak_current_amps),
            ..*m
        },
        ..*a
    }
}

/// What a sweep runs: the tuned motor's configuration for each combination, in grid order,
/// and the steps every run is measured on.
struct Plan {
    own: Gains,
    grid: Vec<(Gains, DjiConfig)>,
    windows: Vec<StepWindow>,
}

fn plan(scenario: &Scenario, spec: &SweepSpec) -> Result<Plan, SweepError> {
    let base = base_config(scenario, spec.motor)?;
    let windows = motor_step_windows(&scenario.targets, spec.motor, scenario.duration_ms);
    if windows.is_empty() {
        return Err(SweepError::NoStep);
    }
    let angles = windows.iter().filter(|w| is_angle(w.kind)).count();
    if angles != 0 && angles != windows.len() {
        return Err(SweepError::MixedSteps);
    }
    if spec.tuned == Loop::Angle && angles == 0 {
        return Err(SweepError::AngleLoopUnused);
    }
    let g = &spec.grid;
    if g.kp.is_empty() && g.ki.is_empty() && g.kd.is_empty() {
        return Err(SweepError::NothingToSweep);
    }
    let own = match spec.tuned {
        Loop::Speed => base.cascade.speed,
        Loop::Angle => base.cascade.angle,
    };
    let or_own = |list: &[f32], own: f32| {
        if list.is_empty() {
            vec![own]
        } else {
            list.to_vec()
        }
    };
    let (kps, kis, kds) = (
        or_own(&g.kp, own.kp),
        or_own(&g.ki, own.ki),
        or_own(&g.kd, own.kd),
    );
    if spec.seeds == 0 {
        return Err(SweepError::NoSeeds);
    }
    let count = kps
        .len()
        .saturating_mul(kis.len())
        .saturating_mul(kds.len());
    let runs = count.saturating_mul(spec.seeds as usize);
    if runs > MAX_RUNS {
        return Err(SweepError::TooManyRuns { runs });
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
    Ok(Plan {
        own: Gains {
            kp: own.kp,
            ki: own.ki,
            kd: own.kd,
        },
        grid,
        windows,
    })
}

/// Everything [`sweep`] refuses before it runs anything, checked without running: for a
/// caller that prepares output first.
pub fn check(scenario: &Scenario, spec: &SweepSpec) -> Result<(), SweepError> {
    plan(scenario, spec).map(|_| ())
}

/// Sets the flag if the thread unwinds while it lives: the other threads stop taking runs
/// when one panics, as when one fails.
struct StopOnPanic<'a>(&'a AtomicBool);

impl Drop for StopOnPanic<'_> {
    fn drop(&mut self) {
        if std::thread::panicking() {
            self.0.store(true, Ordering::Relaxed);
        }
    }
}

/// Runs `scenario` with its own gains and with every combination of `spec.grid`, each
/// under `spec.seeds` seeds, on up to `jobs` threads (this one included; at least one, at
/// most [`MAX_JOBS`] and one per simulation), calling `progress` from those threads, in no
/// set order, with the number of simulations done so far (of `(combinations + 1) · seeds`). The scenario's other motors and everything else stay as they are; the
/// tuned loop keeps its other settings (limits, deadband; the cascade sets the angle loop's
/// error mode). Every run keeps its whole trace while it is measured: a long scenario with
/// many motors takes its trace's memory once per thread.
pub fn sweep(
    scenario: &Scenario,
    spec: &SweepSpec,
    jobs: usize,
    progress: &(dyn Fn(usize) + Sync),
) -> Result<SweepOutcome, SweepError> {
    let Plan { own, grid, windows } = plan(scenario, spec)?;
    let seeds = spec.seeds as usize;
    // Simulation `t` is seed `t % seeds` of combination `t / seeds`: the scenario's own gains
    // (0), then the grid's, so every simulation, the baseline's too, is shared out alike.
    let total = grid.len().saturating_add(1).saturating_mul(seeds);
    let simulate = |t: usize| -> Result<Vec<MeasuredStep>, SimError> {
        let mut s = scenario.clone();
        let combination = t.checked_div(seeds).unwrap_or(0);
        if let Some((_, cfg)) = combination.checked_sub(1).and_then(|i| grid.get(i))
            && let Some(m) = s.motors.get_mut(spec.motor)
        {
            m.controller = Controller::Rc10With(*cfg);
        }
        let k = t.checked_rem(seeds).unwrap_or(0) as u64;
        s.seed = scenario.seed.wrapping_add(k);
        let r = run(&s)?;
        Ok(windows
            .iter()
            .map(|w| measure_step(&r.samples, spec.motor, w))
            .collect())
    };

    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let work = || {
        let _stop = StopOnPanic(&failed);
        let mut mine = Vec::new();
        while !failed.load(Ordering::Relaxed) {
            let t = next.fetch_add(1, Ordering::Relaxed);
            if t >= total {
                break;
            }
            let result = simulate(t);
            if result.is_err() {
                // The sweep fails with it: the other threads stop taking runs.
                failed.store(true, Ordering::Relaxed);
            }
            mine.push((t, result));
            progress(done.fetch_add(1, Ordering::Relaxed).saturating_add(1));
        }
        mine
    };
    let mut results: Vec<(usize, Result<Vec<MeasuredStep>, SimError>)> =
        std::thread::scope(|scope| {
            // Threads the system refuses are done without: this thread works too.
            let helpers: Vec<_> = (1..jobs.clamp(1, total.clamp(1, MAX_JOBS)))
                .filter_map(|_| std::thread::Builder::new().spawn_scoped(scope, work).ok())
                .collect();
            let mut all = work();
            for helper in helpers {
                match helper.join() {
                    Ok(mine) => all.extend(mine),
                    // A run that panicked takes the sweep down with it, as it would alone.
                    Err(panic) => std::panic::resume_unwind(panic),
                }
            }
            all
        });
    results.sort_by_key(|(t, _)| *t);
    let simulations = results
        .into_iter()
        .map(|(_, r)| r)
        .collect::<Result<Vec<_>, _>>()
        .map_err(SweepError::Run)?;
    // Each combination's seeds, in seed order, folded into its worst figures.
    let mut folded = simulations.chunks(seeds.max(1)).map(|of_one| {
        let mut seeds = of_one.iter();
        let first = seeds.next().cloned().unwrap_or_default();
        seeds.fold(first, |so_far, these| {
            so_far.iter().zip(these).map(|(a, b)| worse(a, b)).collect()
        })
    });
    let baseline = SweepRun {
        index: None,
        gains: own,
        steps: folded.next().unwrap_or_default(),
    };
    let runs = grid
        .iter()
        .zip(folded)
        .enumerate()
        .map(|(index, (&(gains, _), steps))| SweepRun {
            index: Some(index),
            gains,
            steps,
        })
        .collect();
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
        let worst = |f: fn(&MeasuredStep) -> Option<f64>| {
            run.steps
                .iter()
                .map(f)
                .try_fold(0.0f64, |acc, v| v.map(|v| acc.max(v)))
        };
        let largest = |f: fn(&MeasuredStep) -> f64| run.steps.iter().map(f).fold(0.0f64, f64::max);
        Row {
            rise_s: worst(|s| s.metrics.rise_time_s),
            overshoot_percent: largest(|s| s.metrics.overshoot_percent),
            settling_s: worst(|s| s.metrics.settling_time_s),
            steady_error: largest(|s| s.metrics.steady_state_error),
            iae: run.iae(),
            peak_amps: largest(|s| s.metrics.peak_current_amps),
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

/// The unit of the steps' error (rpm or deg; the sweep refuses mixed steps).
fn error_unit(outcome: &SweepOutcome) -> &'static str {
    outcome
        .baseline
        .steps
        .first()
        .map_or("rpm", |s| crate::output::unit(s.kind))
}

/// The scenario's own gains (with the rank they would have), then the best `top` runs, as a
/// table; figures are the worst of the motor's steps, IAE their sum.
pub fn table(outcome: &SweepOutcome, max_overshoot_percent: f64, top: usize) -> String {
    use fmt::Write as _;
    let u = error_unit(outcome);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<9} {:>11} {:>11} {:>11} {:>10} {:>10} {:>10} {:>14} {:>15} {:>9}  qualifies",
        "rank", "kp", "ki", "kd", "rise", "overshoot", "settle 2%", "steady err", "IAE", "peak I",
    );
    let mut line = |rank: String, run: &SweepRun| {
        let r = Row::of(run);
        let _ = writeln!(
            s,
            "{rank:<9} {:>11} {:>11} {:>11} {:>10} {:>9.2}% {:>10} {:>10.3} {u:<3} {:>15} {:>7.2} A  {}",
            gain(run.gains.kp),
            gain(run.gains.ki),
            gain(run.gains.kd),
            crate::output::opt_ms(r.rise_s),
            r.overshoot_percent,
            crate::output::opt_ms(r.settling_s),
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
    let baseline_rank = outcome.baseline_rank(max_overshoot_percent);
    line(format!("({baseline_rank})"), &outcome.baseline);
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

/// Writes the scenario's own run (index `scenario`) and every run in grid order as CSV: the
/// gains, whether it qualifies, the IAE sum, then each step's figures (rise and settling in
/// ms, empty when never reached).
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
            ",step{i}_at_ms,step{i}_rise_ms,step{i}_overshoot_percent,step{i}_settling_ms,\
             step{i}_steady_error_{u},step{i}_peak_amps"
        )?;
    }
    writeln!(out)?;
    let opt = |v: Option<f64>| v.map_or_else(String::new, |s| format!("{:.3}", s * 1e3));
    let baseline = std::iter::once(("scenario".to_string(), &outcome.baseline));
    let grid = outcome.runs.iter().map(|r| {
        let index = r
            .index
            .map_or_else(|| "scenario".to_string(), |i| i.to_string());
        (index, r)
    });
    for (index, run) in baseline.chain(grid) {
        write!(
            out,
            "{index},{},{},{},{},{}",
            run.gains.kp,
            run.gains.ki,
            run.gains.kd,
            u8::from(run.qualifies(max_overshoot_percent)),
            run.iae()
        )?;
        for step in &run.steps {
            let m = &step.metrics;
            write!(
                out,
                ",{},{},{},{},{},{}",
                step.at_ms,
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
    use crate::metrics::{StepMetrics, min_speed_rise_time_s};
    use crate::plant::MotorParams;
    use crate::scenario::{TargetSpec, builtin_named};

    fn scenario(name: &str) -> Scenario {
        builtin_named(name).unwrap_or_else(|| panic!("no scenario {name}"))
    }

    fn speed_spec(grid: GainGrid) -> SweepSpec {
        SweepSpec {
            motor: 0,
            tuned: Loop::Speed,
            grid,
            max_overshoot_percent: 5.0,
            seeds: 1,
        }
    }

    fn kp_only(kp: Vec<f32>) -> GainGrid {
        GainGrid {
            kp,
            ..GainGrid::default()
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
        assert_eq!(parse_values("1e3,-2").unwrap(), vec![1000.0, -2.0]);
        assert_eq!(
            parse_values("0:1:5,7").unwrap(),
            vec![0.0, 0.25, 0.5, 0.75, 1.0, 7.0]
        );
        // Both ends exactly, however the step rounds.
        let v = parse_values("0.1:0.7:7").unwrap();
        assert_eq!((v.len(), v[0], v[6]), (7, 0.1, 0.7));
        assert_eq!(
            parse_values(" -2 : -1 : 3 ").unwrap(),
            vec![-2.0, -1.5, -1.0]
        );
        assert_eq!(parse_values("2:1:3").unwrap(), vec![2.0, 1.5, 1.0]);
        use ValueListError as E;
        for (bad, error) in [
            ("", E::NotANumber(String::new())),
            ("x", E::NotANumber("x".into())),
            ("1,,2", E::NotANumber(String::new())),
            ("nan", E::NotFinite("nan".into())),
            ("inf", E::NotFinite("inf".into())),
            ("1:2", E::BadForm("1:2".into())),
            ("1:2:3:4", E::BadForm("1:2:3:4".into())),
            ("1:2:x", E::BadCount("1:2:x".into())),
            ("1:2:0", E::BadCount("1:2:0".into())),
            // One value is written as the number; a range of one would drop its end.
            ("3:9:1", E::BadCount("3:9:1".into())),
            ("1,1", E::Repeated(1.0)),
            ("0:0:3", E::Repeated(0.0)),
            ("0:1:3,0.5", E::Repeated(0.5)),
            ("0:1:60000,2:3:60000", E::TooMany),
        ] {
            assert_eq!(parse_values(bad), Err(error), "{bad:?}");
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
        assert!(out.runs.iter().enumerate().all(|(i, r)| r.index == Some(i)));
        assert_eq!(out.baseline.index, None);
        // The shipped M3508 speed loop is kp 0.6, ki 8: the baseline, and the grid's run of the
        // same gains gives the same figures (the same simulation).
        assert_eq!((out.baseline.gains.kp, out.baseline.gains.ki), (0.6, 8.0));
        assert_eq!(out.runs[4].steps, out.baseline.steps);
        // The profile holds 0 rpm from 0 ms (no step: the motor is there) and steps to 300 at
        // 10 ms: one step, measured as the run's own table measures it.
        let steps = &out.baseline.steps;
        assert_eq!(steps.len(), 1);
        assert_eq!((steps[0].at_ms, steps[0].window_ms), (10, 390));
        let table = run(&scenario("m3508-speed-step")).unwrap().metrics;
        assert_eq!(steps[0].metrics, table[0].metrics);
    }

    #[test]
    fn every_step_of_a_profile_is_measured_until_the_next() {
        let mut s = scenario("m3508-speed-step");
        s.targets[0].steps = vec![(0, 0.0), (10, 300.0), (100, 300.0), (200, -100.0)];
        let out = sweep(&s, &speed_spec(kp_only(vec![0.6])), 1, &|_| {}).unwrap();
        let steps = &out.baseline.steps;
        // The hold at 0 ms and the repeated 300 at 100 ms are no steps: the first window runs
        // on to 200 ms.
        assert_eq!(steps.len(), 2, "{steps:?}");
        assert_eq!((steps[0].at_ms, steps[0].window_ms), (10, 190));
        assert_eq!((steps[1].at_ms, steps[1].window_ms), (200, 200));
        // The first settled 49 ms after its step (the shipped gains), so the second starts
        // from within 2 % of 300 rpm.
        let second = steps[1].metrics;
        assert!((second.initial - 300.0).abs() < 6.0, "{second:?}");
        assert_eq!(second.target, -100.0);
        // Its settling counts from its own step, within its own window.
        assert!(
            second.settling_time_s.is_some_and(|t| t < 0.18),
            "{second:?}"
        );
        // The last step is the profile's last: the run's own table has the same figures.
        let table = run(&s).unwrap().metrics;
        assert_eq!(second, table[0].metrics);
    }

    #[test]
    fn the_steps_come_from_the_profiles_alone() {
        let profile = |kind, steps: Vec<(u64, f32)>| TargetSpec {
            motor: 0,
            kind,
            steps,
        };
        let at = |w: &[StepWindow]| -> Vec<(u64, u64, f32)> {
            w.iter().map(|w| (w.at_ms, w.until_ms, w.value)).collect()
        };
        // An opening hold where the motor starts is no step; the step after it runs until
        // the next change, a current target included; past the run, nothing.
        let targets = [
            profile(TargetKind::Rpm, vec![(0, 0.0), (10, 300.0), (50, 300.0)]),
            profile(TargetKind::Current, vec![(100, 1.0)]),
            profile(TargetKind::Rpm, vec![(150, -50.0), (400, 10.0)]),
        ];
        assert_eq!(
            at(&motor_step_windows(&targets, 0, 400)),
            [(10, 100, 300.0), (150, 400, -50.0)]
        );
        assert!(motor_step_windows(&targets, 1, 400).is_empty());
        // Of two entries on one ms, the one a tick applies last; 450° is 90° again, 360° at
        // the start is where the motor is.
        let angles = [
            profile(
                TargetKind::AngleDeg,
                vec![(0, 360.0), (10, 90.0), (20, 450.0)],
            ),
            profile(TargetKind::AngleDeg, vec![(10, 45.0), (30, -270.0)]),
        ];
        assert_eq!(
            at(&motor_step_windows(&angles, 0, 100)),
            [(10, 20, 45.0), (20, 100, 450.0)]
        );
        // -270° after 450° (90°) is the same angle: no step; the window runs to the end.
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
        let many = sweep(&s, &spec, usize::MAX, &|_| {}).unwrap();
        assert_eq!(one, two);
        assert_eq!(one, many);
        // Seeds of one combination shared out between threads fold the same.
        let seeded = SweepSpec { seeds: 3, ..spec };
        assert_eq!(
            sweep(&s, &seeded, 1, &|_| {}).unwrap(),
            sweep(&s, &seeded, 4, &|_| {}).unwrap()
        );
    }

    #[test]
    fn a_loop_too_weak_to_use_the_current_ranks_below_one_that_uses_it() {
        // kp 0.01 A/rpm asks for 3 A at the 300 rpm step, a sixth of the 20 A the C620 can
        // give: the rise takes several times the full-current minimum, and with ki 0.1 A per
        // rpm·s the integral cannot make that up within the 400 ms run; with ki 8 it winds
        // up against a loop with almost no damping (ζ ≈ 0.03 by the formula of
        // `a_stiffer_integral_overshoots_and_drops_out_under_a_tight_limit`) and swings far
        // past. kp 0.6 asks for 180 A: full current, the fastest rise there is.
        let spec = speed_spec(GainGrid {
            kp: vec![0.01, 0.6],
            ki: vec![0.1, 8.0],
            kd: vec![],
        });
        let s = scenario("m3508-speed-step");
        let out = sweep(&s, &spec, 2, &|_| {}).unwrap();
        let ranked = out.ranked(5.0);
        for run in &ranked[..2] {
            assert_eq!(run.gains.kp, 0.6, "{run:?}");
            assert!(run.qualifies(5.0), "{run:?}");
        }
        for run in &ranked[2..] {
            assert_eq!(run.gains.kp, 0.01, "{run:?}");
            assert!(!run.qualifies(5.0), "{run:?}");
        }
        let min = min_speed_rise_time_s(
            MotorParams::for_model(s.motors[0].model),
            s.motors[0].load,
            300.0,
        )
        .unwrap();
        let weakest = out.runs[0].steps[0].metrics;
        assert_eq!((out.runs[0].gains.kp, out.runs[0].gains.ki), (0.01, 0.1));
        assert!(
            weakest.rise_time_s.is_none_or(|r| r > 3.0 * min),
            "{weakest:?}"
        );
        let swinging = out.runs[1].steps[0].metrics;
        assert!(swinging.overshoot_percent > 5.0, "{swinging:?}");
    }

    fn synthetic(
        index: usize,
        overshoot_percent: f64,
        settling_s: Option<f64>,
        iae: f64,
    ) -> SweepRun {
        SweepRun {
            index: Some(index),
            gains: Gains {
                kp: index as f32,
                ki: 0.0,
                kd: 0.0,
            },
            steps: vec![MeasuredStep {
                kind: TargetKind::Rpm,
                at_ms: 10,
                window_ms: 400,
                metrics: StepMetrics {
                    initial: 0.0,
                    target: 100.0,
                    rise_time_s: Some(0.01),
                    overshoot_percent,
                    settling_time_s: settling_s,
                    steady_state_error: 0.0,
                    iae,
                    peak_current_amps: 1.0,
                },
            }],
        }
    }

    #[test]
    fn qualifying_runs_rank_first_each_group_by_error_then_grid_order() {
        let settled = Some(0.05);
        // A step at 200 ms settled at the sample of 560 ms, as the metrics compute it.
        let ms = |t: u64| std::hint::black_box(t) as f64 * 1e-3;
        let just_in_time_s = ms(560) - ms(200);
        assert!(just_in_time_s > 0.36);
        let runs = vec![
            synthetic(0, 9.0, settled, 1.0), // overshoots: out, however small its error
            synthetic(1, 1.0, settled, 3.0), // in
            synthetic(2, 0.0, None, 0.5),    // never settles: out
            synthetic(3, 5.0, settled, 2.0), // in: at the limit counts
            synthetic(4, 2.0, settled, 2.0), // in, the same error as 3: after it
            synthetic(5, 9.0, settled, 4.0), // out
            // Settled only in the last tenth of its 400 ms window (after 360 ms): out.
            synthetic(6, 0.0, Some(0.37), 0.1),
            // Just in time: in (as computed from ms stamps, 0.36000000000000004 s).
            synthetic(7, 0.0, Some(just_in_time_s), 5.0),
        ];
        let outcome = SweepOutcome {
            baseline: SweepRun {
                index: None,
                ..synthetic(0, 0.0, settled, 2.0)
            },
            runs,
        };
        let indices = |ranked: Vec<&SweepRun>| -> Vec<usize> {
            ranked.iter().map(|r| r.index.unwrap()).collect()
        };
        let order = indices(outcome.ranked(5.0));
        assert_eq!(order, [3, 4, 1, 7, 6, 2, 0, 5]);
        // The baseline's 2.0 ties runs 3 and 4 and ranks after them.
        assert_eq!(outcome.baseline_rank(5.0), 3);
        // With no limit to speak of, only settling counts.
        let order = indices(outcome.ranked(100.0));
        assert_eq!(order, [0, 3, 4, 1, 5, 7, 6, 2]);
        // Nothing measured qualifies for nothing.
        let unmeasured = SweepRun {
            steps: Vec::new(),
            ..synthetic(8, 0.0, settled, 0.0)
        };
        assert!(!unmeasured.qualifies(100.0));
    }

    #[test]
    fn a_stiffer_integral_overshoots_and_drops_out_under_a_tight_limit() {
        // Past the current limit the speed loop is PI on J·dω/dt = kt·i: damping
        // ζ = kt·kp / (2·√(J·kt·ki)), with kp and ki in A per rad/s. For the M3508 at the
        // output (J ≈ 6.5e-3 kg·m², kt ≈ 0.25 N·m/A), kp 0.6 A/rpm = 5.7 A/(rad/s): ki 8
        // A/(rpm·s) gives ζ ≈ 2 (overdamped: the documented 0.5 % of the shipped gains),
        // ki 120 gives ζ ≈ 0.5 (underdamped: it swings past).
        let spec = speed_spec(GainGrid {
            kp: vec![0.6],
            ki: vec![8.0, 120.0],
            kd: vec![],
        });
        let out = sweep(&scenario("m3508-speed-step"), &spec, 1, &|_| {}).unwrap();
        let soft = out.runs[0].steps[0].metrics;
        let stiff = out.runs[1].steps[0].metrics;
        assert!(soft.overshoot_percent < 1.0, "{soft:?}");
        assert!(stiff.overshoot_percent > 2.0, "{stiff:?}");
        assert!(out.runs[0].qualifies(1.0));
        assert!(!out.runs[1].qualifies(1.0));
        assert_eq!(out.ranked(1.0)[0].index, Some(0));
    }

    #[test]
    fn an_angle_sweep_tunes_the_angle_loop() {
        let s = scenario("m3508-angle-step");
        assert_eq!(default_loop(&s, 0), Loop::Angle);
        let spec = SweepSpec {
            motor: 0,
            tuned: Loop::Angle,
            grid: kp_only(vec![1.0, 8.0]),
            max_overshoot_percent: 5.0,
            seeds: 1,
        };
        let out = sweep(&s, &spec, 2, &|_| {}).unwrap();
        // The shipped angle loop is kp 8 rpm/deg: the grid's second run is the baseline.
        assert_eq!(out.runs[1].steps, out.baseline.steps);
        let slow = out.runs[0].steps[0];
        let fast = out.runs[1].steps[0];
        assert_eq!(fast.kind, TargetKind::AngleDeg);
        // 0° to 350° is 10° backwards, the short way.
        let m = fast.metrics;
        assert!((m.target - m.initial + 10.0).abs() < 1e-6, "{m:?}");
        assert!(out.runs[1].qualifies(5.0), "{m:?}");
        // 1 rpm per degree of error (6°/s per degree) closes the step with a time constant of
        // 1/6 s; 8 rpm per degree in 21 ms, plus the time to accelerate.
        assert!(slow.metrics.iae > 3.0 * m.iae, "{slow:?} {fast:?}");
    }

    #[test]
    fn the_tuned_loop_keeps_the_limits_it_was_given() {
        // A scenario file's speed loop limited to 5 A: every candidate asks for far more at
        // the 300 rpm step (kp·300 ≥ 180 A) and gets 5 A.
        let mut s = scenario("m3508-speed-step");
        let mut cfg = DjiConfig::default_for(s.motors[0].model);
        cfg.cascade.speed.output_limit = 5.0;
        s.motors[0].controller = Controller::Rc10With(cfg);
        let out = sweep(&s, &speed_spec(kp_only(vec![0.6, 1.2])), 2, &|_| {}).unwrap();
        for run in out.runs.iter().chain([&out.baseline]) {
            let peak = run.steps[0].metrics.peak_current_amps;
            assert!(peak > 4.9 && peak <= 5.0 + 1e-9, "{run:?}");
        }
    }

    #[test]
    fn the_default_motor_is_the_first_rc10_motor_with_a_step() {
        assert_eq!(default_motor(&scenario("m3508-speed-step")), Some(0));
        assert_eq!(default_motor(&scenario("m3508-speed-step-rc10lib")), None);
        let mut s = scenario("fault-power-cut");
        assert_eq!(default_motor(&s), Some(0));
        s.motors[0].controller = Controller::Rc10Legacy;
        assert_eq!(default_motor(&s), Some(1));
        for t in &mut s.targets {
            t.steps = vec![(s.duration_ms, 100.0)];
        }
        assert_eq!(default_motor(&s), None);
    }

    #[test]
    fn refused_sweeps_say_why() {
        let s = scenario("m3508-speed-step");
        let with_motor = |motor| SweepSpec {
            motor,
            ..speed_spec(kp_only(vec![0.5]))
        };
        assert_eq!(
            sweep(&s, &with_motor(1), 1, &|_| {}),
            Err(SweepError::NoMotor {
                motor: 1,
                motors: 1
            })
        );
        let legacy = scenario("m3508-speed-step-rc10lib");
        assert_eq!(
            sweep(&legacy, &with_motor(0), 1, &|_| {}),
            Err(SweepError::LegacyController)
        );
        let chassis = scenario("chassis-remote-drive");
        assert_eq!(
            sweep(&chassis, &with_motor(0), 1, &|_| {}),
            Err(SweepError::NoStep)
        );
        // A step after the end of the run: nothing to rank by.
        let mut late = s.clone();
        late.targets[0].steps = vec![(late.duration_ms + 100, 300.0)];
        assert_eq!(
            sweep(&late, &with_motor(0), 1, &|_| {}),
            Err(SweepError::NoStep)
        );
        let mut mixed = s.clone();
        mixed.targets.push(TargetSpec {
            motor: 0,
            kind: TargetKind::AngleDeg,
            steps: vec![(200, 90.0)],
        });
        assert_eq!(
            sweep(&mixed, &with_motor(0), 1, &|_| {}),
            Err(SweepError::MixedSteps)
        );
        // An opening speed hold before angle steps is no speed step: not mixed.
        let mut held = scenario("m3508-angle-step");
        held.targets.insert(
            0,
            TargetSpec {
                motor: 0,
                kind: TargetKind::Rpm,
                steps: vec![(0, 0.0)],
            },
        );
        let angle_sweep = SweepSpec {
            tuned: Loop::Angle,
            ..with_motor(0)
        };
        assert_eq!(check(&held, &angle_sweep), Ok(()));
        let angle_of_speed = SweepSpec {
            tuned: Loop::Angle,
            ..with_motor(0)
        };
        assert_eq!(
            sweep(&s, &angle_of_speed, 1, &|_| {}),
            Err(SweepError::AngleLoopUnused)
        );
        assert_eq!(
            sweep(&s, &speed_spec(GainGrid::default()), 1, &|_| {}),
            Err(SweepError::NothingToSweep)
        );
        // Through the library (the command line's lists refuse it): a gain that is not finite.
        let infinite = speed_spec(kp_only(vec![0.5, f32::INFINITY]));
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
    fn several_seeds_give_each_step_the_worst_of_them() {
        // Motor 2 of the power-cut scenario runs through 5 % frame loss and 1 % corrupted
        // frames: each seed loses other frames.
        let s = scenario("fault-power-cut");
        let spec = |seeds| SweepSpec {
            motor: 1,
            seeds,
            ..speed_spec(kp_only(vec![0.3, 0.6]))
        };
        let all = sweep(&s, &spec(3), 2, &|_| {}).unwrap();
        let each: Vec<SweepOutcome> = (0..3)
            .map(|k| {
                let mut seeded = s.clone();
                seeded.seed = s.seed + k;
                sweep(&seeded, &spec(1), 1, &|_| {}).unwrap()
            })
            .collect();
        let iae = |o: &SweepOutcome, run: usize| o.runs[run].steps[0].metrics.iae;
        assert!(
            iae(&each[0], 0) != iae(&each[1], 0) || iae(&each[0], 0) != iae(&each[2], 0),
            "the seed changes nothing"
        );
        for run in 0..2 {
            let worst = |f: fn(&StepMetrics) -> f64| {
                each.iter()
                    .map(|o| f(&o.runs[run].steps[0].metrics))
                    .fold(f64::MIN, f64::max)
            };
            let m = all.runs[run].steps[0].metrics;
            assert_eq!(m.iae, worst(|m| m.iae));
            assert_eq!(m.overshoot_percent, worst(|m| m.overshoot_percent));
            assert_eq!(m.peak_current_amps, worst(|m| m.peak_current_amps));
            assert_eq!(m.steady_state_error, worst(|m| m.steady_state_error));
            let settled: Option<Vec<f64>> = each
                .iter()
                .map(|o| o.runs[run].steps[0].metrics.settling_time_s)
                .collect();
            assert_eq!(
                m.settling_time_s,
                settled.map(|t| t.into_iter().fold(f64::MIN, f64::max))
            );
        }
        // Neither the first seed's figures nor the last's: the worst of each figure.
        let differs = |k: usize| {
            (0..2).any(|run| all.runs[run].steps[0].metrics != each[k].runs[run].steps[0].metrics)
        };
        assert!(differs(0) && differs(2));
        assert_eq!(sweep(&s, &spec(0), 1, &|_| {}), Err(SweepError::NoSeeds));
        let many = SweepSpec {
            seeds: 200,
            grid: kp_only(vec![1.0; 1000]),
            ..spec(1)
        };
        assert_eq!(
            sweep(&s, &many, 1, &|_| {}),
            Err(SweepError::TooManyRuns { runs: 200_000 })
        );
    }

    #[test]
    fn progress_counts_every_simulation() {
        let calls = AtomicUsize::new(0);
        let highest = AtomicUsize::new(0);
        let spec = SweepSpec {
            seeds: 2,
            ..speed_spec(kp_only(vec![0.4, 0.5, 0.6]))
        };
        sweep(&scenario("m3508-speed-step"), &spec, 2, &|n| {
            calls.fetch_add(1, Ordering::Relaxed);
            highest.fetch_max(n, Ordering::Relaxed);
        })
        .unwrap();
        // The scenario's gains and three combinations, under two seeds each.
        assert_eq!(calls.load(Ordering::Relaxed), 8);
        assert_eq!(highest.load(Ordering::Relaxed), 8);
    }

    #[test]
    fn the_csv_holds_the_scenario_and_every_run_with_every_step() {
        let mut s = scenario("m3508-speed-step");
        s.targets[0].steps = vec![(10, 300.0), (200, 0.0)];
        let out = sweep(&s, &speed_spec(kp_only(vec![0.3, 0.6])), 1, &|_| {}).unwrap();
        let path = std::env::temp_dir().join(format!("rc10-sweep-{}.csv", std::process::id()));
        write_csv(&out, 5.0, &path).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 4, "{text}");
        let header: Vec<&str> = lines[0].split(',').collect();
        assert_eq!(header.len(), 6 + 2 * 6);
        assert_eq!(header[5], "iae_rpm_s");
        assert_eq!(header[6], "step1_at_ms");
        assert_eq!(header[12], "step2_at_ms");
        for (line, index) in lines[1..].iter().zip(["scenario", "0", "1"]) {
            let fields: Vec<&str> = line.split(',').collect();
            assert_eq!(fields.len(), header.len(), "{line}");
            assert_eq!(fields[0], index);
            assert_eq!((fields[6], fields[12]), ("10", "200"));
        }
        assert!(lines[2].starts_with("0,0.3,8,0,"), "{text}");
    }
}
