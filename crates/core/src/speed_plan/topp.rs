//! Time-optimal parameterisation of one revolution by the phase-plane method: the state is
//! b = ω² (ω = dC/dt) on a grid in C, the control α = dω/dt = ½·db/dC is constant on each
//! interval (so b is linear in C between nodes and b_{i+1} = b_i + 2Δ·α_i), and the limits at
//! node i bound b_i (the velocity limit curve) and α_i (an interval that depends on b_i).
//!
//! This is the discrete form of Bobrow's and Shin & McKay's forward and backward
//! integration, in the reachability form of TOPP-RA (Pham & Pham, 2018): a forward pass
//! caps each node by what the previous one can reach with the largest admissible α, and a
//! backward pass caps it by what still lets the next one be reached with the smallest. Both
//! maps are monotone, so repeating them from the velocity limit curve converges from above to
//! the greatest profile satisfying every constraint, which is the time-optimal one. Repeating
//! round the circle until nothing changes makes the profile close on itself over 360°.
//!
//! The velocity limit curve holds only values of b at which α = 0 is admissible, so every
//! node can always cruise: this makes both passes well defined and the fixed point exist (a
//! constant speed at the curve's minimum satisfies every bound).

/// Bounds at one node. Acceleration limits: −`x_accel_max` ≤ x2·b + x1·α ≤ `x_accel_max`
/// and |α| ≤ `c_accel_max`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhaseNode {
    /// Largest admissible b = ω², rad²/s².
    pub b_max: f64,
    /// dX/dC, mm/rad.
    pub x1: f64,
    /// d²X/dC², mm/rad².
    pub x2: f64,
    /// X acceleration limit, mm/s².
    pub x_accel_max: f64,
    /// C acceleration limit, rad/s².
    pub c_accel_max: f64,
}

/// One periodic phase-plane problem: nodes at equal steps of `step_rad` round the circle.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseProblem {
    pub step_rad: f64,
    pub nodes: Vec<PhaseNode>,
}

/// A bound linear in b: (slope, constant).
type Linear = (f64, f64);

/// Rounds of both passes before giving up on convergence (each round is one revolution in
/// each direction; real profiles settle in three or four).
const MAX_ROUNDS: usize = 200;

impl PhaseNode {
    /// The admissible α at state `b`: the linear bounds as (slope in b, constant) pairs, lower
    /// bounds and upper bounds. The X bound: x1·α ∈ [−a − x2·b, a − x2·b].
    fn alpha_bounds(&self) -> ([Linear; 2], [Linear; 2]) {
        let (a, c) = (self.x_accel_max, self.c_accel_max);
        let flat = ((0.0, -c), (0.0, c));
        // Below 1e-9 mm/rad, X′·α is below 1e-6 mm/s² for any C acceleration a machine has:
        // the X acceleration does not depend on α there, and the velocity limit curve
        // already keeps |x2|·b ≤ a.
        let (x_lo, x_hi) = if self.x1.abs() < 1e-9 {
            ((0.0, f64::NEG_INFINITY), (0.0, f64::INFINITY))
        } else {
            let lo = (-self.x2 / self.x1, -a / self.x1);
            let hi = (-self.x2 / self.x1, a / self.x1);
            // Dividing by a negative x1 swaps the bounds.
            if self.x1 > 0.0 { (lo, hi) } else { (hi, lo) }
        };
        ([flat.0, x_lo], [flat.1, x_hi])
    }

    /// Largest admissible α at `b`.
    pub fn alpha_max(&self, b: f64) -> f64 {
        let (_, hi) = self.alpha_bounds();
        hi.iter()
            .map(|(m, k)| m * b + k)
            .fold(f64::INFINITY, f64::min)
    }

    /// Smallest admissible α at `b`.
    pub fn alpha_min(&self, b: f64) -> f64 {
        let (lo, _) = self.alpha_bounds();
        lo.iter()
            .map(|(m, k)| m * b + k)
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// The time-optimal periodic profile b_i (rad²/s²) of `problem`.
pub fn time_optimal_profile(problem: &PhaseProblem) -> Vec<f64> {
    let n = problem.nodes.len();
    let two_step = 2.0 * problem.step_rad;
    let mut b: Vec<f64> = problem
        .nodes
        .iter()
        .map(|node| node.b_max.max(0.0))
        .collect();
    let scale = b.iter().fold(0.0f64, |m, &v| m.max(v)).max(1e-300);
    for _ in 0..MAX_ROUNDS {
        let mut changed = 0.0f64;
        // Forward: b_{i+1} ≤ b_i + 2Δ·α_max(b_i).
        for i in 0..n {
            let j = (i + 1) % n;
            let reach = b[i] + two_step * problem.nodes[i].alpha_max(b[i]);
            if reach < b[j] {
                changed = changed.max(b[j] - reach.max(0.0));
                b[j] = reach.max(0.0);
            }
        }
        // Backward: b_i ≤ the largest b with b + 2Δ·α_min(b) ≤ b_{i+1}.
        for i in (0..n).rev() {
            let j = (i + 1) % n;
            let cap = backward_cap(&problem.nodes[i], two_step, b[i], b[j]);
            if cap < b[i] {
                changed = changed.max(b[i] - cap);
                b[i] = cap;
            }
        }
        if changed <= 1e-13 * scale {
            break;
        }
    }
    b
}

/// The largest b ≤ `b_now` from which node `node` can still reach `b_next`:
/// g(b) = b + 2Δ·α_min(b) ≤ b_next. g is the maximum of linear functions of b (α_min is), so
/// the set where it holds is an interval, found piece by piece. It is never empty below the
/// velocity limit curve: b = min(b_now, b_next) cruises.
fn backward_cap(node: &PhaseNode, two_step: f64, b_now: f64, b_next: f64) -> f64 {
    if b_now + two_step * node.alpha_min(b_now) <= b_next {
        return b_now;
    }
    let (lo, _) = node.alpha_bounds();
    let mut upper = b_now;
    for (m, k) in lo {
        // (1 + 2Δ·m)·b + 2Δ·k ≤ b_next
        let slope = 1.0 + two_step * m;
        if slope > 0.0 && k.is_finite() {
            upper = upper.min((b_next - two_step * k) / slope);
        }
    }
    upper.max(b_now.min(b_next)).max(0.0)
}

/// Time to run the profile once round, s: on each interval ω² is linear in C, so the time
/// there is exactly 2Δ/(ω_i + ω_{i+1}).
pub fn revolution_time_s(step_rad: f64, b: &[f64]) -> f64 {
    let n = b.len();
    (0..n)
        .map(|i| 2.0 * step_rad / (b[i].sqrt() + b[(i + 1) % n].sqrt()))
        .sum()
}
