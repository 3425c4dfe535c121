//! Chords placed by tolerance: the step law the control runs, the search for its factors,
//! the deviation of a chord from the exact curve, and the fixed step it is compared with.
//!
//! The step law is `Δu = KF / sqrt(W(u) + C0)`, where W = κ·|p′|² is the chord-height rate of
//! the curve (a chord over Δu rises about W·Δu²/8), KF = k·sqrt(8·tol) and C0 caps the step
//! where the curve is nearly straight (at an inflection W is 0 but the third derivative still
//! bends the chord). The generator searches k and the cap until every chord, measured
//! against the exact curve with the endpoints as written, is within the tolerance.

use super::curve::Curve;

/// Written positions are rounded to this many decimals.
pub type Decimals = usize;

/// The step law's constants.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepLaw {
    pub kf: f64,
    pub c0: f64,
}

/// Interior samples per chord before refinement: enough to bracket the one bump a chord
/// short enough for a µm tolerance has.
const SAMPLES: usize = 24;

/// Round to `decimals` decimals, as the program text does: through the text's own
/// formatter, so the value is exactly the one written.
pub(crate) fn round_to(v: f64, decimals: Decimals) -> f64 {
    crate::dialect::fixed(v, decimals).parse().unwrap_or(v)
}

/// Distance from `p` to the segment `a`–`b` (points as (z, x)).
pub(crate) fn segment_distance(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dz, dx) = (b.0 - a.0, b.1 - a.1);
    let len2 = dz * dz + dx * dx;
    let t = if len2 > 0.0 {
        (((p.0 - a.0) * dz + (p.1 - a.1) * dx) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p.0 - a.0 - t * dz).hypot(p.1 - a.1 - t * dx)
}

/// Largest distance of the exact curve between `u0` and `u1` from the chord `a`–`b`:
/// sampled, then refined by golden-section search around the largest sample.
pub(crate) fn chord_deviation(
    curve: &Curve,
    u0: f64,
    u1: f64,
    a: (f64, f64),
    b: (f64, f64),
) -> f64 {
    let dist = |u: f64| {
        let j = curve.jet(u);
        segment_distance((j.z, j.x), a, b)
    };
    let step = (u1 - u0) / SAMPLES as f64;
    let (mut best_i, mut best) = (0, dist(u0));
    for i in 1..=SAMPLES {
        let d = dist(u0 + step * i as f64);
        if d > best {
            best = d;
            best_i = i;
        }
    }
    let lo = u0 + step * best_i.saturating_sub(1) as f64;
    let hi = (u0 + step * (best_i + 1) as f64).min(u1);
    best.max(golden_max(dist, lo, hi))
}

/// Maximum of a one-bump function on [lo, hi] by golden-section search.
fn golden_max(f: impl Fn(f64) -> f64, lo: f64, hi: f64) -> f64 {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut a, mut b) = (lo, hi);
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..40 {
        if f1 >= f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = f(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = f(x2);
        }
    }
    f1.max(f2)
}

/// Parameter values of a walk from 0 to `span` by `du(u)`, the last one clamped to `span`,
/// exactly as the loop runs it: `u = u + du; if u > span { u = span }`.
pub fn walk(span: f64, du: impl Fn(f64) -> f64, max_points: usize) -> Option<Vec<f64>> {
    let mut us = vec![0.0];
    let mut u = 0.0;
    while u < span {
        u += du(u);
        if u > span {
            u = span;
        }
        us.push(u);
        if us.len() > max_points {
            return None;
        }
    }
    Some(us)
}

/// Worst deviation of the chords through `points` (as written) at parameters `us`.
pub(crate) fn worst_deviation(curve: &Curve, us: &[f64], points: &[(f64, f64)]) -> (usize, f64) {
    let mut worst = (0, 0.0);
    for i in 0..us.len() - 1 {
        let d = chord_deviation(curve, us[i], us[i + 1], points[i], points[i + 1]);
        if d > worst.1 {
            worst = (i, d);
        }
    }
    worst
}

/// Fewest chords of equal parameter step whose worst deviation (endpoints rounded to
/// `decimals`) is at most `target_mm`, with that deviation; `None` beyond `max_chords`.
pub(crate) fn fixed_step_for(
    curve: &Curve,
    target_mm: f64,
    decimals: Decimals,
    max_chords: usize,
) -> Option<(usize, f64)> {
    let span = curve.span();
    let worst = |n: usize| {
        let us: Vec<f64> = (0..=n).map(|i| span * i as f64 / n as f64).collect();
        let pts: Vec<(f64, f64)> = us
            .iter()
            .map(|&u| {
                let j = curve.jet(u);
                (round_to(j.z, decimals), round_to(j.x, decimals))
            })
            .collect();
        worst_deviation(curve, &us, &pts).1
    };
    // Grow until it holds, then bisect: the worst chord error falls with the step.
    let mut hi = 1;
    while worst(hi) > target_mm {
        hi *= 2;
        if hi > max_chords {
            return None;
        }
    }
    let mut lo = hi / 2;
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if worst(mid) > target_mm {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some((hi, worst(hi)))
}
