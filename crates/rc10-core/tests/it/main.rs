//! rc10-core's integration tests, one module per subject, linked into one test binary (one
//! link instead of nine: faster `cargo test` and much faster mutation testing, where every
//! mutant rebuilds every test binary).

mod async_runners;
mod bus_rules;
mod can_parts;
mod dm_commands;
mod edges;
mod error_messages;
mod filters_and_limiters;
mod fuzz_regressions;
mod more_devices;
mod motor_trait;
mod prop_chassis;
mod prop_commands;
mod prop_encoder;
mod prop_pid;
mod prop_protocols;
mod receiver_backoff;
mod remotes;
mod small_apis;
