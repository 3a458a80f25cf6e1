//! Metrics of time histories (the vertical cut, theory §9 M6): collapse
//! onset, reversals of a stress history after its peak and the smoothness of
//! its fall. Histories are `(t, value)` pairs with non-decreasing t.

use super::{MetricsError, Result};

/// First time at which `|value|` exceeds `threshold` (linear interpolation
/// between the samples around the crossing); `None` if it never does.
pub fn first_exceedance(history: &[(f64, f64)], threshold: f64) -> Option<f64> {
    let mut previous: Option<(f64, f64)> = None;
    for &(t, v) in history {
        let v = v.abs();
        if v > threshold {
            return Some(match previous {
                Some((t0, v0)) if v > v0 => t0 + (t - t0) * (threshold - v0) / (v - v0),
                _ => t,
            });
        }
        previous = Some((t, v));
    }
    None
}

/// Number of reversals of a history from `start` on, counted with a
/// hysteresis of `threshold`: a reversal is recorded when the value moves
/// by more than `threshold` against the current direction from its last
/// extreme (M6's "sign changes of dq_B/dt", insensitive to wiggles smaller
/// than the threshold).
pub fn reversals(history: &[(f64, f64)], start: f64, threshold: f64) -> usize {
    let mut values = history.iter().filter(|(t, _)| *t >= start).map(|p| p.1);
    let Some(first) = values.next() else {
        return 0;
    };
    let (mut extreme, mut direction, mut count) = (first, 0i8, 0usize);
    for v in values {
        match direction {
            0 => {
                if (v - extreme).abs() > threshold {
                    direction = if v > extreme { 1 } else { -1 };
                    extreme = v;
                }
            }
            1 if v > extreme => extreme = v,
            -1 if v < extreme => extreme = v,
            _ => {
                if (v - extreme).abs() > threshold {
                    direction = -direction;
                    extreme = v;
                    count += 1;
                }
            }
        }
    }
    count
}

/// Smoothness of the fall of a history from its first sample (e.g. a stress
/// peak) to its last: the total variation Σ|Δq| over the net drop
/// q_first − q_last. 1 for a monotone fall; larger when the value rises again
/// on the way (paper Fig. 11: local runs). Fails if the history does not end
/// below its first value.
pub fn fall_roughness(history: &[(f64, f64)]) -> Result<f64> {
    let (Some(first), Some(last)) = (history.first(), history.last()) else {
        return Err(MetricsError::Empty("history"));
    };
    let drop = first.1 - last.1;
    if drop.is_nan() || drop <= 0.0 {
        return Err(MetricsError::Degenerate(
            "the history does not end below its first value",
        ));
    }
    let variation: f64 = history.windows(2).map(|w| (w[1].1 - w[0].1).abs()).sum();
    Ok(variation / drop)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sampled(f: impl Fn(f64) -> f64, n: usize, t_end: f64) -> Vec<(f64, f64)> {
        (0..=n)
            .map(|i| {
                let t = t_end * i as f64 / n as f64;
                (t, f(t))
            })
            .collect()
    }

    #[test]
    fn exceedance_of_a_ramp_is_interpolated_exactly() {
        // u = 2 t crosses 0.05 at t = 0.025 exactly, between samples
        let h = sampled(|t| -2.0 * t, 7, 0.1);
        let t = first_exceedance(&h, 0.05).unwrap();
        assert!((t - 0.025).abs() < 1e-15, "{t}");
        assert_eq!(first_exceedance(&h, 1.0), None);
    }

    #[test]
    fn reversals_count_oscillations_above_the_threshold_only() {
        // 5 full periods of amplitude 1 on a rising trend: 10 reversals
        let h = sampled(
            |t| (2.0 * std::f64::consts::PI * 5.0 * t).sin() + 0.1 * t,
            2000,
            1.0,
        );
        assert_eq!(reversals(&h, 0.0, 0.5), 10);
        // wiggles of amplitude 1e-3 (318 periods) on a fall: none counted
        // at threshold 1e-2, every one at 1e-4
        let w = sampled(|t| 1.0 - t + 1e-3 * (2000.0 * t).sin(), 20_000, 1.0);
        assert_eq!(reversals(&w, 0.0, 1e-2), 0);
        let n = reversals(&w, 0.0, 1e-4);
        assert!((630..=640).contains(&n), "{n}");
    }

    #[test]
    fn roughness_of_a_monotone_fall_is_one_and_grows_with_a_rebound() {
        let fall = sampled(|t| 0.2 - 0.1 * t, 500, 1.0);
        assert!((fall_roughness(&fall).unwrap() - 1.0).abs() < 1e-12);
        // down to 0 at t = 0.5, back up to 0.1 at the end: variation 0.2 + 0.1, drop 0.1
        let rebound = sampled(
            |t| {
                if t < 0.5 {
                    0.2 * (1.0 - 2.0 * t)
                } else {
                    0.2 * (t - 0.5)
                }
            },
            500,
            1.0,
        );
        let r = fall_roughness(&rebound).unwrap();
        assert!((r - 3.0).abs() < 1e-9, "{r}");
        assert!(fall_roughness(&sampled(|t| t, 10, 1.0)).is_err());
    }
}
