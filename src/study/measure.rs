//! Error measures of a study: a run's monitor history against a reference
//! (a closed form or a reference run's history).

use super::spec::{Measure, Quantity};

/// A monitor's history `(t, value)`, times increasing.
pub type History = [(f64, f64)];

/// What a quantity is compared against.
pub enum Reference<'a> {
    /// A closed form `u(t)` with its period, s.
    ClosedForm {
        /// The reference value at time t.
        value: &'a dyn Fn(f64) -> f64,
        /// The period of the closed form.
        period: f64,
    },
    /// A reference run's history of the same monitor.
    Run(&'a History),
}

impl Reference<'_> {
    fn at(&self, t: f64) -> Option<f64> {
        match self {
            Reference::ClosedForm { value, .. } => Some(value(t)),
            Reference::Run(history) => interpolate(history, t),
        }
    }

    fn period(&self) -> Option<f64> {
        match self {
            // a closed form without a period gives NaN
            Reference::ClosedForm { period, .. } => Some(*period).filter(|p| p.is_finite()),
            Reference::Run(history) => mean_period(history),
        }
    }
}

/// The error of `history` in `quantity`'s measure; `None` when it cannot be
/// measured (the run stopped before the time, no full period, no reference
/// value at the run's times).
pub fn error(quantity: &Quantity, history: &History, reference: &Reference) -> Option<f64> {
    match quantity.measure {
        Measure::L2 => l2_error(history, reference),
        Measure::AtTime => {
            let t = quantity.time?;
            let value = interpolate(history, t)?;
            let scale = scale(history, reference)?;
            Some((value - reference.at(t)?).abs() / scale)
        }
        Measure::Period => {
            let (period, reference) = (mean_period(history)?, reference.period()?);
            Some((period - reference).abs() / reference)
        }
    }
}

/// Relative L2 error in time, trapezoidal weights on the run's rows:
/// ‖u − u_ref‖ / ‖u_ref‖.
fn l2_error(history: &History, reference: &Reference) -> Option<f64> {
    if history.len() < 2 {
        return None;
    }
    let (mut diff2, mut ref2) = (0.0, 0.0);
    for pair in history.windows(2) {
        let w = 0.5 * (pair[1].0 - pair[0].0);
        for &(t, u) in pair {
            let r = reference.at(t)?;
            diff2 += w * (u - r) * (u - r);
            ref2 += w * r * r;
        }
    }
    (ref2 > 0.0).then(|| (diff2 / ref2).sqrt())
}

/// Largest |u_ref| at the run's times (the scale of `at_time` errors).
fn scale(history: &History, reference: &Reference) -> Option<f64> {
    let scale = history
        .iter()
        .filter_map(|&(t, _)| reference.at(t))
        .fold(0.0f64, |m, r| m.max(r.abs()));
    (scale > 0.0).then_some(scale)
}

/// Linear interpolation at `t`; `None` outside the history (1e-9 relative
/// slack at the ends).
pub fn interpolate(history: &History, t: f64) -> Option<f64> {
    let (first, last) = (history.first()?, history.last()?);
    let slack = 1e-9 * (last.0 - first.0).abs().max(f64::MIN_POSITIVE);
    if t < first.0 - slack || t > last.0 + slack {
        return None;
    }
    let k = history.partition_point(|p| p.0 <= t);
    if k == 0 {
        return Some(first.1);
    }
    if k == history.len() {
        return Some(last.1);
    }
    let (a, b) = (history[k - 1], history[k]);
    Some(a.1 + (b.1 - a.1) * (t - a.0) / (b.0 - a.0))
}

/// Mean period between the first and last upward zero crossings (crossing
/// times by linear interpolation); `None` with fewer than two crossings.
pub fn mean_period(history: &History) -> Option<f64> {
    let crossings: Vec<f64> = history
        .windows(2)
        .filter(|w| w[0].1 < 0.0 && w[1].1 >= 0.0)
        .map(|w| w[0].0 + (w[1].0 - w[0].0) * (-w[0].1) / (w[1].1 - w[0].1))
        .collect();
    match crossings.as_slice() {
        [first, .., last] => Some((last - first) / (crossings.len() - 1) as f64),
        _ => None,
    }
}

/// Least-squares slope of log y against log x over the finite positive pairs
/// (the observed order of convergence); `None` with fewer than two.
pub fn log_log_slope(points: &[(f64, f64)]) -> Option<f64> {
    let logs: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite() && *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    if logs.len() < 2 {
        return None;
    }
    let n = logs.len() as f64;
    let (mx, my) = (
        logs.iter().map(|p| p.0).sum::<f64>() / n,
        logs.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = logs.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = logs.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    (sxx > 0.0).then(|| sxy / sxx)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sine(omega: f64, dt: f64, n: usize, phase: f64) -> Vec<(f64, f64)> {
        (0..=n)
            .map(|i| {
                let t = i as f64 * dt;
                (t, (omega * t + phase).sin())
            })
            .collect()
    }

    /// A phase lag φ of a unit sine over whole periods has the relative L2
    /// error |2 sin(φ/2)|; its period error is zero; at_time is the pointwise
    /// difference over the amplitude.
    #[test]
    fn measures_of_a_phase_lag() {
        let omega = 2.0 * std::f64::consts::PI;
        let phi = 0.01;
        let exact = |t: f64| (omega * t).sin();
        let reference = Reference::ClosedForm {
            value: &exact,
            period: 1.0,
        };
        let run = sine(omega, 1e-4, 30_000, -phi);
        let l2 = Quantity {
            monitor: "u".into(),
            measure: Measure::L2,
            time: None,
        };
        let e = error(&l2, &run, &reference).unwrap();
        let expected = 2.0 * (phi / 2.0).sin();
        assert!((e - expected).abs() < 1e-6 * expected, "{e} vs {expected}");
        let period = Quantity {
            measure: Measure::Period,
            ..l2.clone()
        };
        assert!(error(&period, &run, &reference).unwrap() < 1e-6);
        let at = Quantity {
            measure: Measure::AtTime,
            time: Some(2.25),
            ..l2.clone()
        };
        let expected = ((omega * 2.25).sin() - (omega * 2.25 - phi).sin()).abs();
        let e = error(&at, &run, &reference).unwrap();
        assert!((e - expected).abs() < 1e-6, "{e} vs {expected}");
        // past the end of the run: no value
        let late = Quantity {
            time: Some(4.0),
            ..at
        };
        assert_eq!(error(&late, &run, &reference), None);
    }

    /// A reference run is interpolated at the run's times: a run equal to the
    /// reference sampled more coarsely has an error at the interpolation
    /// level (≤ (ω Δt_ref)²/8 relative).
    #[test]
    fn reference_run_is_interpolated() {
        let omega = 2.0 * std::f64::consts::PI;
        let fine = sine(omega, 1e-4, 25_000, 0.0);
        let coarse = sine(omega, 1e-2, 200, 0.0);
        let l2 = Quantity {
            monitor: "u".into(),
            measure: Measure::L2,
            time: None,
        };
        let e = error(&l2, &coarse, &Reference::Run(&fine)).unwrap();
        assert!(e < (omega * 1e-4).powi(2) / 8.0, "{e}");
        let p = mean_period(&fine).unwrap();
        assert!((p - 1.0).abs() < 1e-8, "{p}");
    }

    #[test]
    fn slope_of_a_power_law() {
        let pts: Vec<(f64, f64)> = [1.0, 0.5, 0.25, 0.125]
            .iter()
            .map(|&h| (h, 3.0 * h * h))
            .collect();
        assert!((log_log_slope(&pts).unwrap() - 2.0).abs() < 1e-12);
        assert_eq!(log_log_slope(&pts[..1]), None);
    }
}
