//! Step-response figures of a run's target profiles, measured on the physical signal.

use super::{MotorSample, Sample, TargetKind, TargetSpec};
use crate::metrics::{StepAccumulator, StepMetrics, step_metrics_of};
use rc10_core::math::{wrap_deg_180, wrap_deg_360};

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

/// One step of a motor's target profiles and the time it is measured over: from the step
/// until the motor's next change of target (of any of its profiles, current ones too) or the
/// end of the run. The same for every run of a scenario (see [`motor_step_windows`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepWindow {
    /// What was stepped.
    pub kind: TargetKind,
    /// The target asked for (rpm or degrees).
    pub value: f32,
    /// When, ms.
    pub at_ms: u64,
    /// The end of the window, ms (after `at_ms`).
    pub until_ms: u64,
}

/// One step of a motor, measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeasuredStep {
    /// What was stepped.
    pub kind: TargetKind,
    /// When, ms.
    pub at_ms: u64,
    /// How long the response was measured, ms.
    pub window_ms: u64,
    /// The figures over that window, on the physical signal.
    pub metrics: StepMetrics,
}

/// The speed and angle steps of `motor`'s target profiles in a run of `duration_ms`, in time
/// order, from the profiles alone (so every run of a scenario measures the same steps):
/// - of several entries on the same ms, the last in target order (the one a tick applies
///   last) counts;
/// - an entry that asks for the target already in force (same kind, same value; angles in
///   `[0, 360)`) is no step, nor is a first entry that asks for where every simulated motor
///   starts (0 rpm, 0°): a profile's opening hold;
/// - entries at or after `duration_ms` are never reached.
///
/// Current entries are not measured but end the window of the step before them.
pub fn motor_step_windows(
    targets: &[TargetSpec],
    motor: usize,
    duration_ms: u64,
) -> Vec<StepWindow> {
    let mut entries: Vec<(u64, TargetKind, f32)> = targets
        .iter()
        .filter(|t| t.motor == motor)
        .flat_map(|t| t.steps.iter().map(|&(at_ms, value)| (at_ms, t.kind, value)))
        .filter(|&(at_ms, _, _)| at_ms < duration_ms)
        .collect();
    // Stable: on the same ms, target order, then profile order.
    entries.sort_by_key(|&(at_ms, _, _)| at_ms);
    let in_force = |kind: TargetKind, value: f32| match kind {
        TargetKind::AngleDeg => wrap_deg_360(value),
        _ => value,
    };
    let mut changes: Vec<(u64, TargetKind, f32)> = Vec::with_capacity(entries.len());
    let mut previous: Option<(TargetKind, f32)> = None;
    for (i, &(at_ms, kind, value)) in entries.iter().enumerate() {
        if entries
            .get(i.saturating_add(1))
            .is_some_and(|&(next_ms, _, _)| next_ms == at_ms)
        {
            continue; // replaced on the same ms
        }
        let same = match previous {
            Some((k, v)) => k == kind && in_force(k, v) == in_force(kind, value),
            None => kind != TargetKind::Current && in_force(kind, value) == 0.0,
        };
        if !same {
            changes.push((at_ms, kind, value));
            previous = Some((kind, value));
        }
    }
    changes
        .iter()
        .enumerate()
        .filter(|(_, (_, kind, _))| *kind != TargetKind::Current)
        .map(|(i, &(at_ms, kind, value))| StepWindow {
            kind,
            value,
            at_ms,
            until_ms: changes
                .get(i.saturating_add(1))
                .map_or(duration_ms, |&(t, _, _)| t),
        })
        .collect()
}

/// `window` of `motor` measured in `samples` (a run's, one a ms): from the physical value at
/// its first sample (an angle target taken the short way from there). A window with no
/// sample of the motor (not from a run) has figures that are NaN or none.
pub fn measure_step(samples: &[Sample], motor: usize, window: &StepWindow) -> MeasuredStep {
    let signal = |s: &MotorSample| match window.kind {
        TargetKind::Rpm => s.true_rpm,
        _ => s.true_total_deg,
    };
    let first = samples.partition_point(|s| s.t_ms < window.at_ms);
    let last = samples.partition_point(|s| s.t_ms < window.until_ms);
    let series: Vec<(f64, f64, f64)> = samples
        .get(first..last)
        .unwrap_or(&[])
        .iter()
        .filter_map(|s| {
            let m = s.motors.get(motor)?;
            Some((s.t_ms as f64 * 1e-3, signal(m), m.current_amps))
        })
        .collect();
    let y0 = series.first().map_or(f64::NAN, |&(_, y, _)| y);
    let target = match window.kind {
        // The shortest way from where the motor was.
        TargetKind::AngleDeg => y0 + f64::from(wrap_deg_180(window.value - y0 as f32)),
        _ => f64::from(window.value),
    };
    MeasuredStep {
        kind: window.kind,
        at_ms: window.at_ms,
        window_ms: window.until_ms.saturating_sub(window.at_ms),
        metrics: step_metrics_of(&series, window.at_ms as f64 * 1e-3, y0, target),
    }
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
