//! Step-response figures of a run's target profiles, measured on the physical signal.

use super::{MotorSample, Sample, TargetKind, TargetSpec};
use crate::metrics::{StepAccumulator, StepMetrics, step_metrics_of};
use rc10_core::math::wrap_deg_180;

/// Step metrics of one target profile's last step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetMetrics {
    /// Target index.
    pub target: usize,
    /// Motor index.
    pub motor: usize,
    /// What was stepped.
    pub kind: TargetKind,
    /// The figures.
    pub metrics: StepMetrics,
}

/// Step metrics of each target profile's last step, on the physical signal, in target order
/// (current targets and targets without steps have none). `samples` are in time order.
///
/// One pass over the samples folds every target's figures at once, without collecting its
/// series: a long run's samples do not fit in the caches (reading them once per target cost
/// as much as a tenth of the run), and the series of a minute-long run were megabytes of
/// fresh memory.
pub(super) fn target_metrics(targets: &[TargetSpec], samples: &[Sample]) -> Vec<TargetMetrics> {
    /// A target's step and its figures so far.
    struct Step {
        index: usize,
        motor: usize,
        kind: TargetKind,
        at_ms: u64,
        /// Index of the first sample at or after the step.
        first: usize,
        figures: StepAccumulator,
        /// Whether a sample after the step lacks this motor (so the response is shorter
        /// than announced to `figures`).
        gap: bool,
    }
    let signal = |kind: TargetKind, s: &MotorSample| match kind {
        TargetKind::Rpm => s.true_rpm,
        _ => s.true_total_deg,
    };
    let mut steps: Vec<Step> = targets
        .iter()
        .enumerate()
        .filter(|(_, spec)| spec.kind != TargetKind::Current)
        .filter_map(|(index, spec)| {
            let &(at_ms, value) = spec.steps.last()?;
            let first = samples.partition_point(|s| s.t_ms < at_ms);
            let before = samples.get(first)?.motors.get(spec.motor)?;
            let y0 = signal(spec.kind, before);
            let target = match spec.kind {
                // The shortest way from where the motor was.
                TargetKind::AngleDeg => y0 + f64::from(wrap_deg_180(value - y0 as f32)),
                _ => f64::from(value),
            };
            let len = samples.len() - first;
            Some(Step {
                index,
                motor: spec.motor,
                kind: spec.kind,
                at_ms,
                first,
                figures: StepAccumulator::new(len, at_ms as f64 * 1e-3, y0, target),
                gap: false,
            })
        })
        .collect();
    let earliest = steps.iter().map(|s| s.first).min().unwrap_or(samples.len());
    for s in samples.get(earliest..).unwrap_or(&[]) {
        let t_s = s.t_ms as f64 * 1e-3;
        for step in &mut steps {
            // `t_ms ≥ at_ms` already gives `t ≥ t0_s` (the same rounded scaling of both).
            if s.t_ms >= step.at_ms {
                match s.motors.get(step.motor) {
                    Some(m) => step.figures.push(t_s, signal(step.kind, m), m.current_amps),
                    None => step.gap = true,
                }
            }
        }
    }
    steps
        .into_iter()
        .map(|step| {
            let metrics = if step.gap {
                // Samples without the motor (not from a run, whose samples all hold every
                // motor): the response is the samples that have it.
                let series: Vec<(f64, f64, f64)> = samples
                    .get(step.first..)
                    .unwrap_or(&[])
                    .iter()
                    .filter_map(|s| {
                        let m = s.motors.get(step.motor)?;
                        Some((s.t_ms as f64 * 1e-3, signal(step.kind, m), m.current_amps))
                    })
                    .collect();
                let f = step.figures.finish();
                step_metrics_of(&series, step.at_ms as f64 * 1e-3, f.initial, f.target)
            } else {
                step.figures.finish()
            };
            TargetMetrics {
                target: step.index,
                motor: step.motor,
                kind: step.kind,
                metrics,
            }
        })
        .collect()
}

/// One step of a motor's target profiles, measured over its window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredStep {
    /// What was stepped.
    pub kind: TargetKind,
    /// When, ms.
    pub at_ms: u64,
    /// How long the response was measured, ms: until the motor's next step (of any of its
    /// target profiles) or the end of the run.
    pub window_ms: u64,
    /// The figures over that window.
    pub metrics: StepMetrics,
}

/// Every speed and angle step of `motor`'s target profiles, in time order (profiles in
/// target order on the same ms), each measured on the physical signal from its step until the
/// motor's next step of any profile (current ones too) or the end of `samples`.
///
/// Not steps, and not measured: an entry that repeats the motor's previous one (same kind,
/// same value), one that asks for where the motor already is (a profile's "hold 0 rpm" at
/// 0 ms), one with no sample in its window (replaced on the same ms, or after the end). The
/// motor's last step is measured as [`target_metrics`] measures its profile's last step, to
/// the bit.
pub(crate) fn motor_steps(
    targets: &[TargetSpec],
    samples: &[Sample],
    motor: usize,
) -> Vec<MeasuredStep> {
    let mut entries: Vec<(u64, TargetKind, f32)> = targets
        .iter()
        .filter(|t| t.motor == motor)
        .flat_map(|t| t.steps.iter().map(|&(at_ms, value)| (at_ms, t.kind, value)))
        .collect();
    entries.sort_by_key(|&(at_ms, _, _)| at_ms);
    let mut changes: Vec<(u64, TargetKind, f32)> = Vec::with_capacity(entries.len());
    for e in entries {
        if changes
            .last()
            .is_some_and(|&(_, kind, value)| kind == e.1 && value == e.2)
        {
            continue;
        }
        changes.push(e);
    }
    let end_ms = samples.last().map_or(0, |s| s.t_ms.saturating_add(1));
    let signal = |kind: TargetKind, s: &MotorSample| match kind {
        TargetKind::Rpm => s.true_rpm,
        _ => s.true_total_deg,
    };
    changes
        .iter()
        .enumerate()
        .filter(|(_, (_, kind, _))| *kind != TargetKind::Current)
        .filter_map(|(i, &(at_ms, kind, value))| {
            let until_ms = changes
                .get(i.saturating_add(1))
                .map_or(end_ms, |&(t, _, _)| t);
            let first = samples.partition_point(|s| s.t_ms < at_ms);
            let last = samples.partition_point(|s| s.t_ms < until_ms);
            let window = samples.get(first..last)?;
            let y0 = signal(kind, window.first()?.motors.get(motor)?);
            let target = match kind {
                // The shortest way from where the motor was.
                TargetKind::AngleDeg => y0 + f64::from(wrap_deg_180(value - y0 as f32)),
                _ => f64::from(value),
            };
            if (target - y0).abs() < 1e-9 {
                return None;
            }
            let series: Vec<(f64, f64, f64)> = window
                .iter()
                .filter_map(|s| {
                    let m = s.motors.get(motor)?;
                    Some((s.t_ms as f64 * 1e-3, signal(kind, m), m.current_amps))
                })
                .collect();
            Some(MeasuredStep {
                kind,
                at_ms,
                window_ms: until_ms.saturating_sub(at_ms),
                metrics: step_metrics_of(&series, at_ms as f64 * 1e-3, y0, target),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 21 ticks (0–20 ms) of two motors: motor 0 holds 350° (5 A at 1 ms, before its step),
    /// motor 1 ramps 10 rpm/ms from 5 ms to 100 rpm (2 A at 7 ms).
    fn samples() -> Vec<Sample> {
        (0..=20u64)
            .map(|t_ms| {
                let m0 = MotorSample {
                    true_total_deg: 350.0,
                    current_amps: if t_ms == 1 { 5.0 } else { 0.0 },
                    ..MotorSample::default()
                };
                let m1 = MotorSample {
                    true_rpm: (t_ms.saturating_sub(5) as f64 * 10.0).min(100.0),
                    current_amps: if t_ms == 7 { 2.0 } else { 0.0 },
                    ..MotorSample::default()
                };
                Sample {
                    t_ms,
                    motors: [m0, m1].into_iter().collect(),
                    chassis: None,
                }
            })
            .collect()
    }

    #[test]
    fn every_target_measures_its_own_last_step_in_one_pass() {
        let target = |motor, kind, steps: &[(u64, f32)]| TargetSpec {
            motor,
            kind,
            steps: steps.to_vec(),
        };
        let targets = [
            target(1, TargetKind::Current, &[(0, 3.0)]),
            target(1, TargetKind::Rpm, &[(0, 0.0), (5, 100.0)]),
            target(0, TargetKind::AngleDeg, &[(2, 10.0)]),
            target(0, TargetKind::Rpm, &[(30, 50.0)]), // after the last sample
            target(1, TargetKind::Rpm, &[]),
        ];
        let m = target_metrics(&targets, &samples());
        assert_eq!(m.len(), 2, "{m:?}");

        let (speed, angle) = (&m[0], &m[1]);
        assert_eq!(
            (speed.target, speed.motor, speed.kind),
            (1, 1, TargetKind::Rpm)
        );
        assert_eq!((speed.metrics.initial, speed.metrics.target), (0.0, 100.0));
        // 10 rpm at 6 ms, 90 rpm at 14 ms.
        let rise = speed.metrics.rise_time_s.unwrap();
        assert!((rise - 0.008).abs() < 1e-12, "{rise}");
        assert_eq!(speed.metrics.peak_current_amps, 2.0);

        assert_eq!((angle.target, angle.motor), (2, 0));
        // From 350° the shortest way to 10° is +20°.
        assert_eq!(
            (angle.metrics.initial, angle.metrics.target),
            (350.0, 370.0)
        );
        assert_eq!(angle.metrics.rise_time_s, None);
        // The 5 A at 1 ms came before this target's step.
        assert_eq!(angle.metrics.peak_current_amps, 0.0);
    }

    #[test]
    fn samples_without_the_motor_are_left_out_of_its_response() {
        // Motor 1's ramp (10 rpm/ms from 5 ms to 100 rpm at 15 ms) without its samples at
        // 6–8 ms: 10 % is first seen at 9 ms (40 rpm), 90 % at 14 ms: rise 5 ms. The IAE
        // integrates each kept sample over the interval to the next: 4 ms · 100 rpm from 5
        // ms, then 1 ms each at 60, 50 … 10 rpm: 0.4 + 0.21 = 0.61 rpm·s. 13 samples from
        // the step: the tail is the last one (100 rpm), no error.
        let samples: Vec<Sample> = samples()
            .into_iter()
            .map(|mut s| {
                if (6..=8).contains(&s.t_ms) {
                    s.motors.truncate(1);
                }
                s
            })
            .collect();
        let targets = [TargetSpec {
            motor: 1,
            kind: TargetKind::Rpm,
            steps: vec![(5, 100.0)],
        }];
        let m = target_metrics(&targets, &samples);
        let f = &m[0].metrics;
        assert!((f.rise_time_s.unwrap() - 0.005).abs() < 1e-12, "{f:?}");
        assert!((f.iae - 0.61).abs() < 1e-9, "{f:?}");
        assert_eq!(f.steady_state_error, 0.0);
        assert!((f.settling_time_s.unwrap() - 0.010).abs() < 1e-12, "{f:?}");
    }
}
