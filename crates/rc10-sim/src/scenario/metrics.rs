//! Step-response figures of a run's target profiles, measured on the physical signal.

use super::{MotorSample, Sample, TargetKind, TargetSpec};
use crate::metrics::{StepMetrics, step_metrics_of};
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
/// One pass over the samples collects every target's series: a long run's samples do not
/// fit in the caches, and reading them once per target cost as much as a tenth of the run.
pub(super) fn target_metrics(targets: &[TargetSpec], samples: &[Sample]) -> Vec<TargetMetrics> {
    /// A target's step and the `(time s, signal, current A)` series after it.
    struct Step {
        index: usize,
        motor: usize,
        kind: TargetKind,
        at_ms: u64,
        y0: f64,
        target: f64,
        series: Vec<(f64, f64, f64)>,
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
            // The first sample at or after the step.
            let first = samples.partition_point(|s| s.t_ms < at_ms);
            let before = samples.get(first)?.motors.get(spec.motor)?;
            let y0 = signal(spec.kind, before);
            let target = match spec.kind {
                // The shortest way from where the motor was.
                TargetKind::AngleDeg => y0 + f64::from(wrap_deg_180(value - y0 as f32)),
                _ => f64::from(value),
            };
            Some(Step {
                index,
                motor: spec.motor,
                kind: spec.kind,
                at_ms,
                y0,
                target,
                series: Vec::with_capacity(samples.len().saturating_sub(first)),
            })
        })
        .collect();
    // What `step_metrics` would collect from separate time, value and current series, built
    // in one go for every target.
    let earliest = steps.iter().map(|s| s.at_ms).min().unwrap_or(u64::MAX);
    let from = samples.partition_point(|s| s.t_ms < earliest);
    for s in samples.get(from..).unwrap_or(&[]) {
        let t_s = s.t_ms as f64 * 1e-3;
        for step in &mut steps {
            // `t_ms ≥ at_ms` already gives `t ≥ t0_s` (the same rounded scaling of both).
            if s.t_ms >= step.at_ms
                && let Some(m) = s.motors.get(step.motor)
            {
                step.series
                    .push((t_s, signal(step.kind, m), m.current_amps));
            }
        }
    }
    steps
        .into_iter()
        .map(|step| TargetMetrics {
            target: step.index,
            motor: step.motor,
            kind: step.kind,
            metrics: step_metrics_of(&step.series, step.at_ms as f64 * 1e-3, step.y0, step.target),
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
}
