//! `rc10-sim`: run a simulated robot and show how its motors respond.
#![forbid(unsafe_code)]

use clap::{Parser, Subcommand, ValueEnum};
use rc10_sim::metrics::min_speed_rise_time_s;
use rc10_sim::plant::MotorParams;
use rc10_sim::scenario::{Scenario, TargetKind, builtin, builtin_named, run_with_progress, soak};
use rc10_sim::sweep::{self, GainGrid, Loop, SweepSpec};
use rc10_sim::{output, scenario};
use std::path::PathBuf;
use std::process::ExitCode;

/// Simulate rc10 motors on a CAN bus and measure their step responses.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run a scenario (default: m3508-speed-step) and write its trace and plot.
    Run(RunArgs),
    /// Run a scenario once for every combination of candidate gains of one motor's speed or
    /// angle loop (on every core) and rank the runs by how well the motor followed its steps.
    Sweep(SweepArgs),
    /// List the built-in scenarios.
    List,
}

/// The loop a sweep tunes.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum LoopArg {
    /// The speed loop (rpm in, amps or volts out).
    Speed,
    /// The angle loop (degrees in, rpm out).
    Angle,
}

/// The scenario a command runs, and what the command line changes of it.
#[derive(Debug, clap::Args)]
struct ScenarioArgs {
    /// Built-in scenario name (see `list`) or a scenario file (`*.toml`).
    #[arg(default_value = "m3508-speed-step")]
    scenario: String,
    /// Simulated duration in ms, of each run of a sweep (default: the scenario's).
    #[arg(long)]
    duration_ms: Option<u64>,
    /// Seed for everything random (a sweep's first seed).
    #[arg(long)]
    seed: Option<u64>,
}

#[derive(Debug, Parser)]
struct SweepArgs {
    #[command(flatten)]
    which: ScenarioArgs,
    /// The motor whose loop is tuned, 1 for the scenario's first (default: the first motor with
    /// a speed or angle step).
    #[arg(long)]
    motor: Option<usize>,
    /// Which loop (default: angle if the motor has an angle target, else speed).
    #[arg(long = "loop", value_enum)]
    tuned: Option<LoopArg>,
    /// Candidate proportional gains: comma-separated numbers and FROM:TO:COUNT ranges, e.g.
    /// `0.2:1.0:5,1.5` (default: the scenario's gain).
    #[arg(long, allow_hyphen_values = true)]
    kp: Option<String>,
    /// Candidate integral gains, per second (as --kp).
    #[arg(long, allow_hyphen_values = true)]
    ki: Option<String>,
    /// Candidate derivative gains, times seconds (as --kp).
    #[arg(long, allow_hyphen_values = true)]
    kd: Option<String>,
    /// The largest overshoot, percent of the step, a run may have and qualify.
    #[arg(long, default_value_t = 5.0)]
    max_overshoot: f64,
    /// How many of the best runs to print.
    #[arg(long, default_value_t = 10)]
    top: usize,
    /// Threads (default: one per core).
    #[arg(long)]
    jobs: Option<usize>,
    /// Seeds each combination runs with (the scenario's seed and those after it); its
    /// figures are the worst of them.
    #[arg(long, default_value_t = 1)]
    seeds: u32,
    /// Output folder for sweep.csv (every combination's gains and figures).
    #[arg(long, default_value = "sim-out")]
    out: PathBuf,
}

#[derive(Debug, Parser)]
struct RunArgs {
    #[command(flatten)]
    which: ScenarioArgs,
    /// Output folder for the CSV trace and SVG plot.
    #[arg(long, default_value = "sim-out")]
    out: PathBuf,
    /// Do not write the plot.
    #[arg(long)]
    no_plot: bool,
    /// Judge the run with the fault soak's checks (offline detection, zero commands while
    /// offline, resumption, ESC ranges, scheduler timing, statistics) and exit non-zero if one
    /// fails. Always on for `fault-soak`.
    #[arg(long)]
    checks: bool,
}

/// Prints to stdout; a closed pipe (`rc10-sim | head`) is not an error worth a panic.
fn say(text: &str) {
    use std::io::Write as _;
    let _ = std::io::stdout().lock().write_all(text.as_bytes());
}

fn find(name: &str) -> Result<Scenario, String> {
    let path = std::path::Path::new(name);
    if name.ends_with(".toml") || path.is_file() {
        return rc10_sim::file::load(path).map_err(|e| format!("{}: {e}", path.display()));
    }
    builtin_named(name).ok_or_else(|| {
        let names: Vec<String> = builtin().into_iter().map(|s| s.name).collect();
        format!("no scenario named `{name}`; built-in: {}", names.join(", "))
    })
}

/// The scenario named on the command line, with the duration and seed given there.
fn find_with(which: &ScenarioArgs) -> Result<Scenario, String> {
    let mut scenario = find(&which.scenario)?;
    if let Some(d) = which.duration_ms {
        if !(1..=rc10_sim::file::MAX_DURATION_MS).contains(&d) {
            return Err(format!(
                "--duration-ms must be 1 to {} (a day)",
                rc10_sim::file::MAX_DURATION_MS
            ));
        }
        scenario.duration_ms = d;
    }
    if let Some(s) = which.seed {
        scenario.seed = s;
    }
    Ok(scenario)
}

fn run_cmd(args: RunArgs) -> Result<(), String> {
    let scenario = find_with(&args.which)?;
    let started = std::time::Instant::now();
    let total_ms = scenario.duration_ms;
    let mut progress = |t_ms: u64| {
        // Long runs show where they are (on stderr, so stdout stays a clean table).
        if total_ms >= 20_000 {
            eprint!("\r  {:>3} %", t_ms * 100 / total_ms);
            if t_ms + 1000 > total_ms {
                eprintln!();
            }
        }
    };
    if args.checks || scenario.name == soak::NAME {
        return run_checked(&scenario, &args, &mut progress, started);
    }
    let result = run_with_progress(&scenario, &mut progress)
        .map_err(|e| format!("scenario `{}`: {e}", scenario.name))?;
    let wall = started.elapsed().as_secs_f64();
    say(&output::summary(&scenario, &result));
    // For unloaded speed steps, compare with the fastest rise full current allows.
    for m in &result.metrics {
        let spec = scenario.motors.get(m.motor);
        if m.kind == TargetKind::Rpm
            && let Some(spec) = spec
            && spec.load == Default::default()
            && m.metrics.initial.abs() < 1.0
            && let Some(min) = min_speed_rise_time_s(
                MotorParams::for_model(spec.model),
                spec.load,
                m.metrics.target,
            )
            && let Some(rise) = m.metrics.rise_time_s
        {
            say(&format!(
                "motor {}: rise {:.1} ms = {:.2} x the full-current minimum {:.1} ms\n",
                m.motor + 1,
                rise * 1e3,
                rise / min,
                min * 1e3
            ));
        }
    }
    let paths = output::write_all(&scenario, &result, &args.out, !args.no_plot)
        .map_err(|e| format!("writing results to {}: {e}", args.out.display()))?;
    for p in paths {
        say(&format!("wrote     {}\n", p.display()));
    }
    say(&format!(
        "speed     {:.0} x real time ({:.3} s wall for {} ms simulated)\n",
        scenario.duration_ms as f64 * 1e-3 / wall.max(1e-9),
        wall,
        scenario.duration_ms
    ));
    Ok(())
}

fn sweep_cmd(args: SweepArgs) -> Result<(), String> {
    let scenario = find_with(&args.which)?;
    let motor = match args.motor {
        Some(0) => return Err("--motor counts from 1".into()),
        Some(n) => n - 1,
        // The sweep says why if there is none to tune.
        None => sweep::default_motor(&scenario).unwrap_or(0),
    };
    let tuned = match args.tuned {
        Some(LoopArg::Speed) => Loop::Speed,
        Some(LoopArg::Angle) => Loop::Angle,
        None => sweep::default_loop(&scenario, motor),
    };
    if !(args.max_overshoot.is_finite() && args.max_overshoot >= 0.0) {
        return Err("--max-overshoot must be a percentage of 0 or more".into());
    }
    let values = |flag: &str, text: &Option<String>| match text {
        Some(t) => sweep::parse_values(t).map_err(|e| format!("--{flag}: {e}")),
        None => Ok(Vec::new()),
    };
    let grid = GainGrid {
        kp: values("kp", &args.kp)?,
        ki: values("ki", &args.ki)?,
        kd: values("kd", &args.kd)?,
    };
    let count = |v: &Vec<f32>| v.len().max(1);
    let runs = count(&grid.kp)
        .saturating_mul(count(&grid.ki))
        .saturating_mul(count(&grid.kd));
    let jobs = args.jobs.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    if jobs == 0 {
        return Err("--jobs must be 1 or more".into());
    }
    if args.seeds == 0 {
        return Err("--seeds must be 1 or more".into());
    }
    // Every simulation: the scenario's gains and each combination, under each seed.
    let simulations = runs.saturating_add(1).saturating_mul(args.seeds as usize);
    let spec = SweepSpec {
        motor,
        tuned,
        grid,
        max_overshoot_percent: args.max_overshoot,
        seeds: args.seeds,
    };
    // What the sweep would refuse, before anything is written; then the output folder,
    // before the runs: a long sweep should not end in a folder that cannot be made.
    sweep::check(&scenario, &spec).map_err(|e| format!("sweep of `{}`: {e}", scenario.name))?;
    std::fs::create_dir_all(&args.out)
        .map_err(|e| format!("creating {}: {e}", args.out.display()))?;
    say(&format!(
        "sweep     {}, motor {}, {tuned} loop: {runs} combination(s) of {} ms{} on {} \
         thread(s), and the scenario's gains (their would-be rank in brackets)\n\n",
        scenario.name,
        motor + 1,
        scenario.duration_ms,
        if args.seeds > 1 {
            format!(
                ", each with {} seeds from {} (the worst shown)",
                args.seeds, scenario.seed
            )
        } else {
            String::new()
        },
        jobs.min(simulations).min(sweep::MAX_JOBS)
    ));
    let started = std::time::Instant::now();
    // On a terminal only (a pipe or a log gets the table alone), and only ever forwards: the
    // threads report in no set order.
    let terminal = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let shown = std::sync::Mutex::new(0usize);
    let progress = |done: usize| {
        if terminal
            && simulations >= 20
            && let Ok(mut shown) = shown.lock()
            && *shown < done
        {
            *shown = done;
            eprint!("\r  {done} / {simulations} simulations");
        }
    };
    let outcome = sweep::sweep(&scenario, &spec, jobs, &progress);
    if terminal && simulations >= 20 {
        eprintln!();
    }
    let outcome = outcome.map_err(|e| format!("sweep of `{}`: {e}", scenario.name))?;
    let wall = started.elapsed().as_secs_f64();
    say(&sweep::table(&outcome, args.max_overshoot, args.top));
    let qualified = outcome
        .runs
        .iter()
        .filter(|r| r.qualifies(args.max_overshoot))
        .count();
    say(&format!(
        "\nqualified {qualified} of {} combinations (every step settles within +/-2 % before \
         the last tenth of its window, overshoot <= {} %)\n",
        outcome.runs.len(),
        args.max_overshoot
    ));
    let csv = args.out.join("sweep.csv");
    sweep::write_csv(&outcome, args.max_overshoot, &csv)
        .map_err(|e| format!("writing {}: {e}", csv.display()))?;
    say(&format!("wrote     {}\n", csv.display()));
    say(&format!(
        "speed     {simulations} simulations in {wall:.2} s ({:.0} a second, {:.0} x real time \
         in all)\n",
        simulations as f64 / wall.max(1e-9),
        simulations as f64 * scenario.duration_ms as f64 * 1e-3 / wall.max(1e-9)
    ));
    Ok(())
}

/// Runs `scenario` under the soak checks: summary, report, trace, plots; an error if a check
/// failed (after everything is written).
fn run_checked(
    scenario: &Scenario,
    args: &RunArgs,
    progress: &mut dyn FnMut(u64),
    started: std::time::Instant,
) -> Result<(), String> {
    let outcome = soak::run_soak(scenario, progress);
    let wall = started.elapsed().as_secs_f64();
    if let Some(result) = &outcome.result {
        say(&output::summary(scenario, result));
        say("\n");
    }
    say(&outcome.report.text());
    if let Some(result) = &outcome.result {
        let paths =
            soak::write_outputs(scenario, result, &outcome.report, &args.out, !args.no_plot)
                .map_err(|e| format!("writing results to {}: {e}", args.out.display()))?;
        for p in paths {
            say(&format!("wrote     {}\n", p.display()));
        }
    }
    say(&format!(
        "speed     {:.0} x real time ({:.3} s wall for {} ms simulated)\n",
        scenario.duration_ms as f64 * 1e-3 / wall.max(1e-9),
        wall,
        scenario.duration_ms
    ));
    let failed = outcome.report.failed();
    if failed.is_empty() {
        Ok(())
    } else {
        let names: Vec<&str> = failed.iter().map(|c| c.title()).collect();
        Err(format!(
            "scenario `{}`: {} check(s) failed: {}",
            scenario.name,
            failed.len(),
            names.join("; ")
        ))
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Command::List) => {
            for s in scenario::builtin() {
                say(&format!("{:<26} {}\n", s.name, s.description));
            }
            Ok(())
        }
        Some(Command::Run(args)) => run_cmd(args),
        Some(Command::Sweep(args)) => sweep_cmd(args),
        None => run_cmd(RunArgs::parse_from(["run"])),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
