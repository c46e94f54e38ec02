//! `rc10-sim`: the simulator's command-line entry point.
#![forbid(unsafe_code)]

fn main() {
    println!(
        "rc10-sim {}: the simulator (simulated CAN bus, motor plants, scenarios) is not built yet.",
        rc10_sim::CORE_VERSION
    );
    println!("See README.md for what works today; `cargo test` runs the algorithm tests.");
}
