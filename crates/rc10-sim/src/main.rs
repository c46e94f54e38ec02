//! `rc10-sim`: run a simulated robot and show how its motors respond.
#![forbid(unsafe_code)]

use clap::{Parser, Subcommand};
use rc10_sim::metrics::min_speed_rise_time_s;
use rc10_sim::plant::MotorParams;
use rc10_sim::scenario::{Scenario, TargetKind, builtin, builtin_named, run_with_progress, soak};
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
    /// List the built-in scenarios.
    List,
}

#[derive(Debug, Parser)]
struct RunArgs {
    /// Built-in scenario name (see `list`) or a scenario file (`*.toml`).
    #[arg(default_value = "m3508-speed-step")]
    scenario: String,
    /// Simulated duration in ms (default: the scenario's).
    #[arg(long)]
    duration_ms: Option<u64>,
    /// Seed for everything random.
    #[arg(long)]
    seed: Option<u64>,
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

fn run_cmd(args: RunArgs) -> Result<(), String> {
    let mut scenario = find(&args.scenario)?;
    if let Some(d) = args.duration_ms {
        if !(1..=rc10_sim::file::MAX_DURATION_MS).contains(&d) {
            return Err(format!(
                "--duration-ms must be 1 to {} (a day)",
                rc10_sim::file::MAX_DURATION_MS
            ));
        }
        scenario.duration_ms = d;
    }
    if let Some(s) = args.seed {
        scenario.seed = s;
    }
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
