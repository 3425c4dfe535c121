//! The analytic turning curves' parameters, each defined once: the library's
//! [`crate::curve::Curve`], the contour file's `[[segment]]`s and the command line's curves
//! (with the `cli` feature) all take these structs, so a new parameter is added in one place.
//! Angles in degrees, lengths in mm (lathe coordinates: z along the axis, x the radius).

use serde::Deserialize;

/// `z = zc + a·cos θ`, `x = xc + b·sin θ`, θ from `start_deg` to `end_deg`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(deny_unknown_fields)]
pub struct Ellipse {
    /// The centre's z.
    #[cfg_attr(feature = "cli", arg(long))]
    pub centre_z_mm: f64,
    /// The centre's x.
    #[cfg_attr(feature = "cli", arg(long))]
    pub centre_x_mm: f64,
    /// The semi-axis along z.
    #[cfg_attr(feature = "cli", arg(long))]
    pub a_mm: f64,
    /// The semi-axis along x.
    #[cfg_attr(feature = "cli", arg(long))]
    pub b_mm: f64,
    /// θ where the cut starts.
    #[cfg_attr(feature = "cli", arg(long))]
    pub start_deg: f64,
    /// θ where the cut ends.
    #[cfg_attr(feature = "cli", arg(long))]
    pub end_deg: f64,
}

/// `(x − x0)² = 2p·(z − z0)`, run along x from `x_start_mm` to `x_end_mm`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(deny_unknown_fields)]
pub struct Parabola {
    /// The vertex's z.
    #[cfg_attr(feature = "cli", arg(long))]
    pub vertex_z_mm: f64,
    /// The vertex's x.
    #[cfg_attr(feature = "cli", arg(long))]
    pub vertex_x_mm: f64,
    /// The parameter p (half the latus rectum).
    #[cfg_attr(feature = "cli", arg(long))]
    pub p_mm: f64,
    /// x where the cut starts.
    #[cfg_attr(feature = "cli", arg(long))]
    pub x_start_mm: f64,
    /// x where the cut ends.
    #[cfg_attr(feature = "cli", arg(long))]
    pub x_end_mm: f64,
}

/// `x = x0 + A·sin(360·z/λ + φ)`, run along z.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(deny_unknown_fields)]
pub struct Sine {
    /// The mean x (x0).
    #[cfg_attr(feature = "cli", arg(long))]
    pub mean_x_mm: f64,
    /// The amplitude A.
    #[cfg_attr(feature = "cli", arg(long))]
    pub amplitude_mm: f64,
    /// The wavelength λ along z.
    #[cfg_attr(feature = "cli", arg(long))]
    pub wavelength_mm: f64,
    /// The phase φ (0 when not given).
    #[serde(default)]
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.0))]
    pub phase_deg: f64,
    /// z where the cut starts.
    #[cfg_attr(feature = "cli", arg(long))]
    pub z_start_mm: f64,
    /// z where the cut ends.
    #[cfg_attr(feature = "cli", arg(long))]
    pub z_end_mm: f64,
}

/// `x = x0 + A·tan(ω·(z − zc))`, ω in degrees per mm, run along z; the argument must stay
/// inside (−90°, 90°).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[serde(deny_unknown_fields)]
pub struct Tangent {
    /// The mean x (x0).
    #[cfg_attr(feature = "cli", arg(long))]
    pub mean_x_mm: f64,
    /// The amplitude A.
    #[cfg_attr(feature = "cli", arg(long))]
    pub amplitude_mm: f64,
    /// The rate ω.
    #[cfg_attr(feature = "cli", arg(long))]
    pub rate_deg_per_mm: f64,
    /// The centre zc, where the tangent is 0.
    #[cfg_attr(feature = "cli", arg(long))]
    pub centre_z_mm: f64,
    /// z where the cut starts.
    #[cfg_attr(feature = "cli", arg(long))]
    pub z_start_mm: f64,
    /// z where the cut ends.
    #[cfg_attr(feature = "cli", arg(long))]
    pub z_end_mm: f64,
}
