//! Step-response figures (rise time, overshoot, settling, steady-state error, IAE, peak
//! current) and the current-limited minimum rise time a step could possibly have.

use crate::plant::{DjiEsc, Load, MotorParams};

/// Figures of one step response, computed on the physical output (not the reported value).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepMetrics {
    /// Value before the step.
    pub initial: f64,
    /// Target after the step.
    pub target: f64,
    /// Time from 10 % to 90 % of the step, seconds (`None` if 90 % was never reached).
    pub rise_time_s: Option<f64>,
    /// Largest excursion beyond the target, percent of the step size.
    pub overshoot_percent: f64,
    /// Time after the step until the response stays within ±2 % of the step size, seconds:
    /// the first sample after the last one outside the band (`None` if it is outside the
    /// band at the end).
    pub settling_time_s: Option<f64>,
    /// Mean absolute error over the last 10 % of the window, in the signal's unit.
    pub steady_state_error: f64,
    /// Integral of the absolute error, signal unit × seconds.
    pub iae: f64,
    /// Largest absolute motor current, amps.
    pub peak_current_amps: f64,
}

/// Computes [`StepMetrics`] for samples `t_s`, `y` (and `current_amps`) from the step at
/// `t0_s` (value `y0`) towards `target`. Samples before `t0_s` are ignored.
pub fn step_metrics(
    t_s: &[f64],
    y: &[f64],
    current_amps: &[f64],
    t0_s: f64,
    y0: f64,
    target: f64,
) -> StepMetrics {
    let samples: Vec<(f64, f64, f64)> = t_s
        .iter()
        .zip(y)
        .zip(current_amps)
        .filter(|((t, _), _)| **t >= t0_s)
        .map(|((t, y), i)| (*t, *y, *i))
        .collect();
    step_metrics_of(&samples, t0_s, y0, target)
}

/// [`step_metrics`] of `(time s, value, current A)` samples, all at or after `t0_s`.
pub(crate) fn step_metrics_of(
    samples: &[(f64, f64, f64)],
    t0_s: f64,
    y0: f64,
    target: f64,
) -> StepMetrics {
    let mut acc = StepAccumulator::new(samples.len(), t0_s, y0, target);
    for &(t_s, value, current_amps) in samples {
        acc.push(t_s, value, current_amps);
    }
    acc.finish()
}

/// [`StepMetrics`] built one sample at a time, without keeping the samples: for a response
/// of `len` samples (all at or after the step), known in advance because the steady-state
/// error averages the last tenth of them. Every figure is folded in sample order, so the
/// result is the same, to the bit, as computing it over the collected series.
#[derive(Debug, Clone)]
pub(crate) struct StepAccumulator {
    t0_s: f64,
    y0: f64,
    target: f64,
    /// Sign of the step (+1, −1; 0 for none).
    dir: f64,
    /// Size of the step (at least `f64::EPSILON`).
    size: f64,
    /// Half-width of the settling band.
    band: f64,
    /// Samples pushed so far.
    count: usize,
    /// Index of the first sample of the steady-state tail.
    tail_from: usize,
    /// First times at 10 % and 90 % of the step.
    t10: Option<f64>,
    t90: Option<f64>,
    overshoot_percent: f64,
    /// Whether the last sample was outside the band, and the settling time so far: 0 until a
    /// sample is outside, none while outside, then from the first sample after it.
    last_outside: bool,
    settling_time_s: Option<f64>,
    tail_sum: f64,
    /// The previous sample's time and value (IAE integrates each over the next interval).
    previous: Option<(f64, f64)>,
    iae: f64,
    peak_current_amps: f64,
}

impl StepAccumulator {
    /// For `len` samples after a step at `t0_s` from `y0` towards `target`.
    pub(crate) fn new(len: usize, t0_s: f64, y0: f64, target: f64) -> Self {
        let delta = target - y0;
        let size = delta.abs().max(f64::EPSILON);
        Self {
            t0_s,
            y0,
            target,
            dir: delta.signum(),
            size,
            band: 0.02 * size,
            count: 0,
            tail_from: len - len / 10,
            t10: None,
            t90: None,
            overshoot_percent: 0.0,
            last_outside: false,
            settling_time_s: Some(0.0),
            // `Sum` for floats starts at −0.0.
            tail_sum: -0.0,
            previous: None,
            iae: -0.0,
            peak_current_amps: 0.0,
        }
    }

    /// The next sample: time in s, value, motor current in A.
    pub(crate) fn push(&mut self, t_s: f64, value: f64, current_amps: f64) {
        let progress = (value - self.y0) * self.dir / self.size;
        if self.t10.is_none() && progress >= 0.1 {
            self.t10 = Some(t_s);
        }
        if self.t90.is_none() && progress >= 0.9 {
            self.t90 = Some(t_s);
        }
        self.overshoot_percent = self.overshoot_percent.max((progress - 1.0) * 100.0);
        // Settled from the first sample after the last one outside the band (the response is
        // known to be inside from then on; between the two samples it is not known).
        let error = (value - self.target).abs();
        let outside = error > self.band;
        if outside {
            self.settling_time_s = None;
        } else if self.last_outside {
            self.settling_time_s = Some(t_s - self.t0_s);
        }
        self.last_outside = outside;
        if self.count >= self.tail_from {
            self.tail_sum += error;
        }
        if let Some((t_prev, v_prev)) = self.previous {
            self.iae += (t_s - t_prev) * (v_prev - self.target).abs();
        }
        self.previous = Some((t_s, value));
        self.peak_current_amps = self.peak_current_amps.max(current_amps.abs());
        self.count += 1;
    }

    /// The figures of the samples pushed (which must be the `len` announced).
    pub(crate) fn finish(&self) -> StepMetrics {
        let tail_len = self.count.saturating_sub(self.tail_from);
        StepMetrics {
            initial: self.y0,
            target: self.target,
            rise_time_s: match (self.t10, self.t90) {
                (Some(a), Some(b)) => Some(b - a),
                _ => None,
            },
            overshoot_percent: self.overshoot_percent,
            settling_time_s: self.settling_time_s,
            steady_state_error: if tail_len == 0 {
                f64::NAN
            } else {
                self.tail_sum / tail_len as f64
            },
            iae: self.iae,
            peak_current_amps: self.peak_current_amps,
        }
    }
}

/// The 10–90 % rise time of a speed step from 0 to `target_rpm` when the ESC is commanded its
/// full current from the first instant (bang-bang): no controller can rise faster on this
/// plant. `None` if full current never reaches 90 % of the target.
pub fn min_speed_rise_time_s(params: MotorParams, load: Load, target_rpm: f64) -> Option<f64> {
    let mut esc = DjiEsc::new(params, 1, load, 0);
    let full = if target_rpm >= 0.0 {
        i16::MAX
    } else {
        i16::MIN + 1
    };
    esc.set_command_raw(full);
    let dt = 1e-5;
    let (mut t10, mut t90) = (None, None);
    for k in 0..200_000u64 {
        let t = k as f64 * dt;
        let n = esc.speed_rpm() / target_rpm;
        if t10.is_none() && n >= 0.1 {
            t10 = Some(t);
        }
        if n >= 0.9 {
            t90 = Some(t);
            break;
        }
        esc.step(k * 10, dt);
    }
    Some(t90? - t10?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_order_step_figures_match_closed_form() {
        // y = 1 - e^{-t/τ}, τ = 0.1 s: rise 10–90 % = τ ln 9 = 0.2197 s; 2 % settling = τ ln 50
        // = 0.391 s; no overshoot; IAE = τ = 0.1.
        let tau = 0.1;
        let t: Vec<f64> = (0..20_000).map(|k| k as f64 * 1e-4).collect();
        let y: Vec<f64> = t.iter().map(|t| 1.0 - (-t / tau).exp()).collect();
        let i = vec![0.5; t.len()];
        let m = step_metrics(&t, &y, &i, 0.0, 0.0, 1.0);
        assert!((m.rise_time_s.unwrap() - 0.2197).abs() < 1e-3);
        assert!((m.settling_time_s.unwrap() - 0.391).abs() < 1e-3);
        assert_eq!(m.overshoot_percent, 0.0);
        assert!((m.iae - 0.1).abs() < 1e-3);
        assert_eq!(m.peak_current_amps, 0.5);
        assert!(m.steady_state_error < 1e-6);
    }

    #[test]
    fn overshoot_and_negative_steps() {
        let t = [0.0, 0.1, 0.2, 0.3, 0.4];
        let y = [0.0, -0.5, -1.2, -1.0, -1.0];
        let m = step_metrics(&t, &y, &[0.0; 5], 0.0, 0.0, -1.0);
        assert!((m.overshoot_percent - 20.0).abs() < 1e-9);
    }

    #[test]
    fn settling_is_the_first_sample_after_the_last_one_outside_the_band() {
        // 1 ms samples; the 2 % band is ±0.02. Last outside at 80 ms (0.97), inside from
        // 81 ms on: it entered the band somewhere in (80, 81] ms, so 81 ms.
        let t: Vec<f64> = (0..200).map(|k| k as f64 * 1e-3).collect();
        let y: Vec<f64> = (0..200)
            .map(|k| if k <= 80 { 0.97 * k as f64 / 80.0 } else { 1.0 })
            .collect();
        let m = step_metrics(&t, &y, &vec![0.0; 200], 0.0, 0.0, 1.0);
        assert!((m.settling_time_s.unwrap() - 0.081).abs() < 1e-12, "{m:?}");
        // Inside from the first sample: settled at once.
        let m = step_metrics(&t, &vec![1.0; 200], &vec![0.0; 200], 0.0, 0.0, 1.0);
        assert_eq!(m.settling_time_s, Some(0.0));
    }

    #[test]
    fn steady_state_error_averages_the_last_tenth_of_the_samples() {
        // 20 samples: the last tenth is the last two, 0.5 and 0.3 off the target of 1: 0.4.
        // The 0.9 off just before them is not in it.
        let t: Vec<f64> = (0..20).map(|k| k as f64 * 1e-3).collect();
        let mut y = vec![1.0; 20];
        (y[17], y[18], y[19]) = (0.1, 1.5, 0.7);
        let m = step_metrics(&t, &y, &[0.0; 20], 0.0, 0.0, 1.0);
        assert!((m.steady_state_error - 0.4).abs() < 1e-12, "{m:?}");
        // Outside the band at the last sample: not settled.
        assert_eq!(m.settling_time_s, None);
        // 50 % overshoot at 18 ms.
        assert!((m.overshoot_percent - 50.0).abs() < 1e-9, "{m:?}");
    }

    #[test]
    fn never_reaching_target_reports_none() {
        let t = [0.0, 0.1, 0.2];
        let y = [0.0, 0.2, 0.3];
        let m = step_metrics(&t, &y, &[0.0; 3], 0.0, 0.0, 1.0);
        assert_eq!(m.rise_time_s, None);
        assert_eq!(m.settling_time_s, None);
    }

    #[test]
    fn m3508_bang_bang_rise_time_matches_hand_estimate() {
        // 0 → 300 rpm: current-limited at 5 N·m up to 491.4 − 5 · 72 ≈ 131 rpm (the line's
        // end, see `zero_torque_rpm`), then the torque–speed line (τ = 49 ms) takes over;
        // 10 % ≈ 4 ms, 90 % ≈ 42 ms → ≈ 38 ms.
        let t = min_speed_rise_time_s(MotorParams::m3508(), Load::default(), 300.0).unwrap();
        assert!(t > 0.033 && t < 0.045, "t = {t}");
    }
}
