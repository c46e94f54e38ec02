//! The bus's dispatch and tick path with fifteen motors of every kind registered (M3508,
//! M2006, GM6020 in voltage and current mode, VESC, Damiao), driven by any sequence of
//! operations: received frames with any ID, DLC, bytes and timestamp (backwards, far ahead,
//! any 64-bit value), clock steps, application calls with any value (NaN, ±inf, huge), mode
//! switches and limits, scheduler ticks, TX-buffer draining and bus-off.
//!
//! The operations and every invariant are in `rc10_fuzz::model` (see its module docs).
#![no_main]

use libfuzzer_sys::fuzz_target;
use rc10_fuzz::fleet::Fleet;
use rc10_fuzz::model::Harness;
use rc10_fuzz::ops::decode_all;

fuzz_target!(|data: &[u8]| {
    let fleet = Fleet::new();
    let mut harness = Harness::new(&fleet);
    for op in decode_all(data) {
        harness.run(&op);
    }
});
