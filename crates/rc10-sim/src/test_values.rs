//! Awkward inputs for the tests of the simulator's hand-written number conversions.

/// `specials` as they are, then every `±(base + offset)` with its two neighbouring floats:
/// the values just inside and outside each rounding edge the caller names.
pub(crate) fn around_edges(specials: &[f64], bases: &[f64], offsets: &[f64]) -> Vec<f64> {
    let mut v = specials.to_vec();
    for base in bases {
        for offset in offsets {
            for sign in [1.0, -1.0] {
                let x: f64 = sign * (base + offset);
                v.extend([x, x.next_up(), x.next_down()]);
            }
        }
    }
    v
}
