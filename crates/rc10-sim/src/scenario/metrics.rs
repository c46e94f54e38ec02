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

/// Step metrics of a target profile's last step, on the physical signal.
pub(super) fn target_metrics(
    index: usize,
    spec: &TargetSpec,
    samples: &[Sample],
) -> Option<TargetMetrics> {
    if spec.kind == TargetKind::Current {
        return None;
    }
    let &(at_ms, value) = spec.steps.last()?;
    let signal = |s: &MotorSample| match spec.kind {
        TargetKind::Rpm => s.true_rpm,
        _ => s.true_total_deg,
    };
    let pick = |s: &Sample| s.motors.get(spec.motor).copied();
    let before = samples.iter().find(|s| s.t_ms >= at_ms).and_then(pick)?;
    let y0 = signal(&before);
    let target = match spec.kind {
        // The shortest way from where the motor was.
        TargetKind::AngleDeg => y0 + f64::from(wrap_deg_180(value - y0 as f32)),
        _ => f64::from(value),
    };
    // What `step_metrics` would collect from separate time, value and current series, built
    // in one go.
    let t0_s = at_ms as f64 * 1e-3;
    let mut series = Vec::with_capacity(samples.len());
    for s in samples.iter().filter(|s| s.t_ms >= at_ms) {
        // `t_ms ≥ at_ms` already gives `t ≥ t0_s` (the same rounded scaling of both).
        if let Some(m) = pick(s) {
            series.push((s.t_ms as f64 * 1e-3, signal(&m), m.current_amps));
        }
    }
    Some(TargetMetrics {
        target: index,
        motor: spec.motor,
        kind: spec.kind,
        metrics: step_metrics_of(&series, t0_s, y0, target),
    })
}
