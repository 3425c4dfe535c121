//! The values a speed-plan table writes at its knots: each rounded up or down to the written
//! resolution so that the slope steps the rounding leaves at the joints are as small as that
//! resolution allows.
//!
//! Why: a POLY block gives the segment's end value and a2, a3; the control takes a1 from the
//! end values (a1 = end − start − a2 − a3). With a2, a3 those of the exact curve, the table
//! as run is the exact curve plus the rounding errors e_k of the knot values joined by
//! straight lines, so its slope steps by (e_{k+1} − e_k)/L_k − (e_k − e_{k−1})/L_{k−1} at
//! knot k. Sampled at an interpolation cycle Δ, a step s shows as an acceleration of up to
//! s/Δ: rounding each knot to its nearest value (steps up to 2q/L for a resolution q) put
//! the demo intake lobe's C acceleration at 103.5 % of its limit at Δ = 0.5 ms, where the
//! plan itself keeps 98 %. Choosing for every knot the value below or above (both within
//! q of the exact one) by dynamic programming minimises the largest step over the whole
//! periodic table.
//!
//! Why not slope-continuous segments instead (a2, a3 chosen so each segment leaves with the
//! slope the previous arrived with): the values still sit on the resolution's grid, so the
//! rounding errors must still be joined, and a C¹ join of errors up to q over a segment of
//! time τ bends by about 6q/τ², which at τ = 0.5 ms and q = 0.1 µm is 2 400 mm/s², three
//! times what the straight join's steps give at Δ = 0.5 ms.

/// The knot values (start of each segment; the end of the last is the first plus the
/// table's gain, exactly) on the grid of `decimals`, for segments starting at `values` with
/// lengths `lengths` in the leading axis. Every value is within one grid step of its exact
/// one, and the largest slope step at a knot (the periodic closing knot included) is the
/// smallest that choice of up or down gives.
pub fn knot_values(values: &[f64], lengths: &[f64], decimals: usize) -> Vec<f64> {
    let n = values.len();
    let q = 10f64.powi(-(decimals.min(15) as i32));
    let lower: Vec<f64> = values.iter().map(|v| (v / q).floor()).collect();
    let nearest = || values.iter().map(|v| (v / q).round() * q).collect();
    if n < 3 || lengths.len() != n || lengths.iter().any(|l| !(l.is_finite() && *l > 0.0)) {
        return nearest();
    }
    // Rounding error, in grid steps, of knot k taking choice c (0 down, 1 up).
    let err = |k: usize, c: usize| lower[k] + c as f64 - values[k] / q;
    let step = |k: usize, (a, b, c): (usize, usize, usize)| {
        let (prev, next) = ((k + n - 1) % n, (k + 1) % n);
        ((err(next, c) - err(k, b)) / lengths[k] - (err(k, b) - err(prev, a)) / lengths[prev]).abs()
    };
    let mut best: Option<(Cost, Vec<usize>)> = None;
    for first in 0..4 {
        let (c0, c1) = (first / 2, first % 2);
        let Some((cost, choice)) = best_path(n, (c0, c1), &step) else {
            continue;
        };
        if best.as_ref().is_none_or(|(b, _)| cost.better(b)) {
            best = Some((cost, choice));
        }
    }
    match best {
        Some((_, choice)) => (0..n).map(|k| (lower[k] + choice[k] as f64) * q).collect(),
        None => nearest(),
    }
}

/// The largest slope step of a path, then the sum of their squares (to prefer the smaller
/// steps among paths with the same largest one).
#[derive(Debug, Clone, Copy)]
struct Cost {
    max: f64,
    sum_sq: f64,
}

impl Cost {
    fn add(self, step: f64) -> Self {
        Self {
            max: self.max.max(step),
            sum_sq: self.sum_sq + step * step,
        }
    }

    fn better(&self, other: &Self) -> bool {
        (self.max, self.sum_sq) < (other.max, other.sum_sq)
    }
}

/// The best choices with knots 0 and 1 fixed to `(c0, c1)`: states are the choices of the
/// last two knots; the step at knot k is known once knot k + 1 is chosen, and the steps at
/// the last knot and at knot 0 once the path closes.
fn best_path(
    n: usize,
    (c0, c1): (usize, usize),
    step: &impl Fn(usize, (usize, usize, usize)) -> f64,
) -> Option<(Cost, Vec<usize>)> {
    let zero = Cost {
        max: 0.0,
        sum_sq: 0.0,
    };
    // cost[a][b]: best cost with knot k − 1 at a and knot k at b.
    let mut cost = [[None::<Cost>; 2]; 2];
    cost[c0][c1] = Some(zero);
    // back[k][b][c]: the choice of knot k − 1 on the best path to (knot k = b, knot k+1 = c).
    let mut back = vec![[[0usize; 2]; 2]; n];
    for (k, back_k) in back.iter_mut().enumerate().take(n - 1).skip(1) {
        let mut next = [[None::<Cost>; 2]; 2];
        for (a, row) in cost.iter().enumerate() {
            for (b, c_ab) in row.iter().enumerate() {
                let Some(c_ab) = c_ab else { continue };
                for c in 0..2 {
                    let candidate = c_ab.add(step(k, (a, b, c)));
                    if next[b][c].is_none_or(|cur| candidate.better(&cur)) {
                        next[b][c] = Some(candidate);
                        back_k[b][c] = a;
                    }
                }
            }
        }
        cost = next;
    }
    let mut end: Option<(Cost, usize, usize)> = None;
    for (a, row) in cost.iter().enumerate() {
        for (b, c_ab) in row.iter().enumerate() {
            let Some(c_ab) = c_ab else { continue };
            let closed = c_ab.add(step(n - 1, (a, b, c0))).add(step(0, (b, c0, c1)));
            if end.as_ref().is_none_or(|(e, _, _)| closed.better(e)) {
                end = Some((closed, a, b));
            }
        }
    }
    let (total, mut a, mut b) = end?;
    let mut choice = vec![0; n];
    choice[n - 1] = b;
    for k in (1..n - 1).rev() {
        choice[k] = a;
        let before = back[k][a][b];
        b = a;
        a = before;
    }
    choice[0] = c0;
    (choice[1] == c1).then_some((total, choice))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The largest slope step of written values `r` against exact `v` (grid steps per unit
    /// length), computed directly.
    fn largest_step(v: &[f64], r: &[f64], l: &[f64], q: f64) -> f64 {
        let n = v.len();
        let e = |k: usize| (r[k % n] - v[k % n]) / q;
        (0..n)
            .map(|k| {
                let p = (k + n - 1) % n;
                ((e(k + 1) - e(k)) / l[k] - (e(k) - e(p)) / l[p]).abs()
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn chosen_values_stay_on_the_grid_within_one_step_and_beat_nearest_rounding() {
        // A smooth curve whose rounding errors are spread over the whole grid step.
        let n = 400;
        let v: Vec<f64> = (0..n)
            .map(|k| 3.0 * (k as f64 * 0.0157).sin() + 0.731 * k as f64 * 1e-3)
            .collect();
        let l: Vec<f64> = (0..n).map(|k| 0.9 + 0.1 * (k % 3) as f64).collect();
        let r = knot_values(&v, &l, 4);
        for (exact, written) in v.iter().zip(&r) {
            assert!((exact - written).abs() < 1e-4 * (1.0 + 1e-9));
            let grid = written * 1e4;
            assert!((grid - grid.round()).abs() < 1e-6, "{written} off the grid");
        }
        let nearest: Vec<f64> = v.iter().map(|x| (x * 1e4).round() / 1e4).collect();
        let ours = largest_step(&v, &r, &l, 1e-4);
        let theirs = largest_step(&v, &nearest, &l, 1e-4);
        // Nearest rounding's steps reach nearly 2 grid steps per length (1.58 here);
        // choosing up or down keeps them within one (0.98 here), the room the planner keeps.
        assert!(theirs > 1.5, "{theirs}");
        assert!(ours <= 1.0, "{ours}");
        assert!(ours < 0.65 * theirs, "{ours} against {theirs}");
    }
}
