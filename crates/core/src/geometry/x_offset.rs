//! What a wheel-centre offset does to the lift: the part ground with its wheel path moved
//! out by a uniform X offset (stock left on, a wheel-head deflection) reads on the gauge as
//! that offset times a gain that depends on the angle, not as a uniform size.
//!
//! Moving the wheel-centre path out by `x` along each ray from the axis moves the path, and
//! the profile it envelops, by `x·cos γ` along the contact normal n (γ between n and the
//! wheel-centre direction ŵ). A flat follower's lift is the support function along n = u,
//! so it reads `x·(n·ŵ)`; a roller's centre and a knife edge move along u by the normal
//! offset over `n·u`. A crankpin read by a flat probe from the main axis is the flat case.
//! Near the base circle γ ≈ 0 and the gain is 1; on a crankpin γ reaches asin(b/(R + r_p)).

use super::{Kind, Part, dot, scale};

impl Part {
    /// Lift change per mm of uniform wheel-centre offset (program X), at follower direction
    /// `psi_rad` of the part frame (for a crankpin: the probe direction from the main axis).
    /// A first-order gain, exact as the offset goes to zero; ≤ 1 for a flat follower.
    pub fn lift_per_x_offset(&self, psi_rad: f64) -> f64 {
        let (sin, cos) = psi_rad.sin_cos();
        let u = [cos, sin];
        match &self.kind {
            Kind::Crankpin(g) => {
                // The pin's point with normal u, and the wheel centre R + r_p out along it.
                let rr = g.wheel_radius_mm + g.pin_radius_mm;
                let w = [g.throw_mm + rr * cos, rr * sin];
                dot(u, w) / dot(w, w).sqrt()
            }
            Kind::Cam { .. } => {
                let p = self.path_point(psi_rad);
                let w_hat = scale(p.w, 1.0 / dot(p.w, p.w).sqrt());
                dot(p.normal, w_hat) / dot(p.normal, p.u)
            }
        }
    }
}
