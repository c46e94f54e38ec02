//! What the speed examples share: their command line.

use rc10_sim::scenario::{Scenario, builtin_named};

/// The command line `[scenario] [ms] [count]`: a built-in scenario (default
/// `chassis-4x-m3508`) set to run for `ms` simulated milliseconds (default 60 000, above 0),
/// and how many times to run it (default 9, at least 2; `count_name` names them in the
/// error, "runs" or "rounds"). Returns the scenario's name, the scenario and the count, or
/// the message for a bad argument.
pub fn scenario_and_count(count_name: &str) -> Result<(String, Scenario, usize), String> {
    let mut args = std::env::args().skip(1);
    let name = args.next().unwrap_or_else(|| "chassis-4x-m3508".into());
    let duration_ms: u64 = match args.next().map(|s| s.parse()) {
        None => 60_000,
        Some(Ok(ms)) if ms > 0 => ms,
        Some(_) => return Err("the duration is a whole number of milliseconds above 0".into()),
    };
    let count: usize = match args.next().map(|s| s.parse()) {
        None => 9,
        Some(Ok(n)) if n >= 2 => n,
        Some(_) => {
            return Err(format!(
                "the number of {count_name} is a whole number, at least 2"
            ));
        }
    };
    let mut scenario =
        builtin_named(&name).ok_or_else(|| format!("no built-in scenario named {name}"))?;
    scenario.duration_ms = duration_ms;
    Ok((name, scenario, count))
}
