//! The wheel-head table: X as a function of C, as points (G1) or cubic segments (POLY).

/// One point of a wheel-head table in the part frame (before machine axis mapping).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TablePoint {
    /// Direction of the wheel centre in the part frame, degrees, in the lift table's sense.
    pub c_deg: f64,
    /// Axis-to-wheel-centre distance, mm.
    pub d_mm: f64,
    /// Program X, mm (`d − R − Rb` for cams, `d − R − r_p` for crankpins).
    pub x_mm: f64,
}

/// One cubic segment of a POLY table: `x(u) = x0 + a1·u + a2·u² + a3·u³`, `u ∈ [0, 1]`
/// running linearly from `c_start_deg` to `c_end_deg`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PolySegment {
    pub c_start_deg: f64,
    pub c_end_deg: f64,
    pub x0_mm: f64,
    pub a1_mm: f64,
    pub a2_mm: f64,
    pub a3_mm: f64,
}

impl PolySegment {
    /// Whether every number of the segment is finite (a table with NaN or ∞ is refused).
    pub fn is_finite(&self) -> bool {
        [
            self.c_start_deg,
            self.c_end_deg,
            self.x0_mm,
            self.a1_mm,
            self.a2_mm,
            self.a3_mm,
        ]
        .iter()
        .all(|v| v.is_finite())
    }

    /// X at the end of the segment (u = 1).
    pub fn x_end_mm(&self) -> f64 {
        self.x0_mm + self.a1_mm + self.a2_mm + self.a3_mm
    }
}
