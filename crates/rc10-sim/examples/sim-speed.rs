//! Simulator speed: simulated time per wall time for a built-in scenario, run several times in
//! one process.
//!
//! ```sh
//! cargo run -p rc10-sim --release --example sim-speed                 # chassis, 60 s, 9 runs
//! cargo run -p rc10-sim --release --example sim-speed -- m3508-speed-step 10000 5
//! ```
//!
//! Arguments (all optional, in order): the scenario name (default `chassis-4x-m3508`), the
//! simulated duration in ms (default 60 000) and the number of runs (default 9). Each run is
//! timed from the start of the simulation to its result (the step metrics included, no file
//! written). The first run meets fresh memory (its samples fault in page by page); the later
//! ones reuse the memory the first freed, as a gain sweep does. Prints every run and the
//! median of the runs after the first.

mod common;

use std::io::Write;
use std::process::ExitCode;
use std::time::Instant;

use rc10_sim::scenario::run;

fn main() -> ExitCode {
    let (name, scenario, runs) = match common::scenario_and_count("runs") {
        Ok(parsed) => parsed,
        Err(message) => {
            eprintln!("{message}");
            return ExitCode::FAILURE;
        }
    };
    let duration_ms = scenario.duration_ms;

    // Written, not printed: a closed pipe (`| head`) ends the program quietly.
    let mut out = std::io::stdout().lock();
    let mut warm = Vec::with_capacity(runs);
    for i in 0..runs {
        let started = Instant::now();
        let result = match run(&scenario) {
            Ok(result) => result,
            Err(e) => {
                eprintln!("{name}: {e}");
                return ExitCode::FAILURE;
            }
        };
        let wall_s = started.elapsed().as_secs_f64();
        let speed = duration_ms as f64 / 1000.0 / wall_s;
        let kind = if i == 0 {
            "fresh memory"
        } else {
            "reused memory"
        };
        if writeln!(
            out,
            "run {:>2}: {speed:>6.0} x real time ({wall_s:.4} s wall, {} samples, {kind})",
            i + 1,
            result.samples.len()
        )
        .is_err()
        {
            return ExitCode::SUCCESS;
        }
        if i > 0 {
            warm.push(speed);
        }
        // Dropped here, before the next run allocates: the next run reuses its memory.
        drop(result);
    }
    warm.sort_by(f64::total_cmp);
    let median = warm.get(warm.len() / 2).copied().unwrap_or(0.0);
    let _ = writeln!(
        out,
        "{name}, {duration_ms} ms simulated: median {median:.0} x real time over runs 2-{runs}"
    );
    ExitCode::SUCCESS
}
