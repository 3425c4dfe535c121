//! The stock on the part through a grinding cycle, revolution by revolution: the depth of
//! cut sets the normal force, the force bends the wheel head back (a stiffness), so the
//! wheel cuts less than commanded where the removal rate is high; spark-out lets the
//! deflection decay. What is left after a stage is the profile that stage leaves.
//!
//! Model, at each degree of C as the wheel passes it (once a revolution): the wheel is
//! commanded `o` above the finished surface and the stock there is `s`. The normal force is
//! the tangential force over the force ratio μ, the tangential force the grinding power
//! over the wheel speed: `F_n = e_c·b·Q′w/(μ·v_s)`, Q′w = `a·(ds/dC)·ω` with `a` the depth
//! cut. The wheel head yields `δ = F_n/k`, so `a = s − (o + δ)` and, with
//! `K = e_c·b·(ds/dC)·ω/(μ·v_s·k)` (mm of deflection per mm of depth), `a = (s − o)/(1 + K)`
//! and `δ = K·a`. A constant infeed f per revolution settles at a = f and δ = K·f; at a fixed
//! `o` the excess `s − o` falls by `K/(1 + K)` per revolution (spark-out).

use super::{Harmonic, StationErrors};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Angles per revolution the stock is followed at (one per degree of C).
pub const STOCK_POINTS: usize = 360;

/// The wheel head and the grinding forces (`[machines.gauge.grinder.stock]`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StockModel {
    /// Wheel-head stiffness against the normal force, N/µm. Default 50.
    pub wheel_head_stiffness_n_um: f64,
    /// Specific grinding energy, J/mm³. Default 40 (hardened steel with a vitrified CBN wheel).
    pub specific_energy_j_mm3: f64,
    /// Tangential over normal force, μ. Default 0.3.
    pub force_ratio: f64,
    /// Wheel width in contact, mm. Default 20.
    pub wheel_width_mm: f64,
    /// Harmonic orders of the stock left on the part that reach the ground outline; higher
    /// orders are dropped (they are far below the gauge's noise). Default 60.
    pub orders: u32,
}

impl Default for StockModel {
    fn default() -> Self {
        Self {
            wheel_head_stiffness_n_um: 50.0,
            specific_energy_j_mm3: 40.0,
            force_ratio: 0.3,
            wheel_width_mm: 20.0,
            orders: 60,
        }
    }
}

impl StockModel {
    /// Every setting that is not a finite number > 0, named.
    pub fn problems(&self) -> Vec<String> {
        let mut p = Vec::new();
        for (name, v) in [
            (
                "stock.wheel_head_stiffness_n_um",
                self.wheel_head_stiffness_n_um,
            ),
            ("stock.specific_energy_j_mm3", self.specific_energy_j_mm3),
            ("stock.force_ratio", self.force_ratio),
            ("stock.wheel_width_mm", self.wheel_width_mm),
        ] {
            if !(v.is_finite() && v > 0.0) {
                p.push(format!("{name} = {v}: must be a finite number > 0"));
            }
        }
        if !(1..=179).contains(&self.orders) {
            p.push(format!("stock.orders = {}: must be 1 to 179", self.orders));
        }
        p
    }

    /// K at an angle whose contact runs `surface_mm_rad` along the profile per radian of C.
    fn compliance(&self, surface_mm_rad: f64, c_speed_rpm: f64, wheel_speed_m_s: f64) -> f64 {
        let omega = c_speed_rpm * TAU / 60.0;
        // J/mm³ is 1000 N/mm², N/µm is 1000 N/mm: the factors cancel.
        self.specific_energy_j_mm3 * self.wheel_width_mm * surface_mm_rad * omega
            / (self.force_ratio * wheel_speed_m_s * 1000.0 * self.wheel_head_stiffness_n_um)
    }
}

/// The stock on one feature: above the finished surface and the wheel head's deflection, mm,
/// at each degree of C.
#[derive(Debug, Clone, PartialEq)]
pub struct Stock {
    pub stock_mm: Vec<f64>,
    pub deflection_mm: Vec<f64>,
}

/// One coupled pass as the control ran it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pass {
    /// X above the curve at the start, mm, and the infeed over the pass (negative: in).
    pub x_offset_mm: f64,
    pub x_infeed_mm: f64,
    pub revolutions: f64,
    pub c_speed_rpm: f64,
    pub wheel_speed_m_s: f64,
}

/// A pass on the speed plan: at each degree of C, where the virtual axis stands (degrees,
/// rising with C through one turn) and C's speed there (rpm). The infeed on X's overlay is
/// spread over VA's travel (`FGROUP(VA)`), and the deflection follows the local C speed.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanPass {
    pub va_deg: Vec<f64>,
    pub c_speed_rpm: Vec<f64>,
}

impl PlanPass {
    /// The plan's law sampled at the stock's points.
    pub fn new(plan: &super::PlannedSpeed) -> Result<Self, super::SimError> {
        let law = super::plan::CLaw::new(plan)?;
        let (va_deg, c_speed_rpm) = (0..STOCK_POINTS)
            .map(|j| {
                let [va, dva_dc, _] = law.inverse((j as f64).to_radians());
                (va.to_degrees(), plan.va_speed_rpm / dva_dc)
            })
            .unzip();
        Ok(Self {
            va_deg,
            c_speed_rpm,
        })
    }
}

impl Stock {
    /// `stock_mm` all round, no deflection.
    pub fn new(stock_mm: f64) -> Self {
        Self {
            stock_mm: vec![stock_mm; STOCK_POINTS],
            deflection_mm: vec![0.0; STOCK_POINTS],
        }
    }

    /// Grinds `pass`; `surface_mm_rad[j]` is the contact's arc per radian of C at j degrees.
    /// The pass starts at C = `start_deg` (whole degrees).
    pub fn grind(
        &mut self,
        model: &StockModel,
        surface_mm_rad: &[f64],
        pass: &Pass,
        start_deg: usize,
    ) {
        self.grind_planned(model, surface_mm_rad, pass, start_deg, None);
    }

    /// [`Self::grind`], on the speed plan when `plan` is given: C's speed at each degree is
    /// the plan's (`pass.c_speed_rpm` is then VA's), and the overlay follows VA's travel.
    pub fn grind_planned(
        &mut self,
        model: &StockModel,
        surface_mm_rad: &[f64],
        pass: &Pass,
        start_deg: usize,
        plan: Option<&PlanPass>,
    ) {
        let n = STOCK_POINTS;
        let steps = (pass.revolutions * n as f64).round() as usize;
        // The leading axis' travel from the pass' start to C's `step`-th degree after it.
        let lead_at = |step: usize| match plan {
            None => step as f64,
            Some(p) => {
                let at =
                    |s: usize| p.va_deg[(start_deg + s) % n] + 360.0 * ((start_deg + s) / n) as f64;
                at(step) - at(0)
            }
        };
        let total = lead_at(steps);
        for step in 0..steps {
            let j = (start_deg + step) % n;
            // The overlay moves in proportion to the leading axis (C, or VA on the plan):
            // where the wheel is at this degree.
            let o = pass.x_offset_mm + pass.x_infeed_mm * lead_at(step + 1) / total;
            let k = model.compliance(
                surface_mm_rad[j % surface_mm_rad.len()],
                plan.map_or(pass.c_speed_rpm, |p| p.c_speed_rpm[j]),
                pass.wheel_speed_m_s,
            );
            let excess = self.stock_mm[j] - o;
            let depth = if excess > 0.0 {
                excess / (1.0 + k)
            } else {
                0.0
            };
            self.stock_mm[j] -= depth;
            self.deflection_mm[j] = k * depth;
        }
    }

    /// The stock as the errors of a station: its mean as size, the rest as harmonics of C up
    /// to `orders` (the ground outline takes them as wheel-centre distance).
    pub fn as_errors(&self, orders: u32) -> StationErrors {
        let n = self.stock_mm.len() as f64;
        let mean = self.stock_mm.iter().sum::<f64>() / n;
        let harmonics = (1..=orders)
            .map(|k| {
                let (mut a, mut b) = (0.0, 0.0);
                for (j, s) in self.stock_mm.iter().enumerate() {
                    let phi = f64::from(k) * (j as f64).to_radians();
                    a += s * phi.cos();
                    b += s * phi.sin();
                }
                let (a, b) = (2.0 * a / n, 2.0 * b / n);
                Harmonic {
                    order: k,
                    amplitude_um: a.hypot(b) * 1000.0,
                    phase_deg: (-b).atan2(a).to_degrees(),
                }
            })
            .collect();
        StationErrors {
            size_um: mean * 1000.0,
            lag_deg: 0.0,
            harmonics,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const R_MM: f64 = 20.0;

    fn round() -> Vec<f64> {
        vec![R_MM; STOCK_POINTS]
    }

    fn pass(offset: f64, infeed: f64, revs: f64) -> Pass {
        Pass {
            x_offset_mm: offset,
            x_infeed_mm: infeed,
            revolutions: revs,
            c_speed_rpm: 30.0,
            wheel_speed_m_s: 35.0,
        }
    }

    /// K by hand for the defaults on a round part of 20 mm at 30 rpm and 35 m/s:
    /// 40·20·20·π / (0.3·35·1000·50) = 0.09574.
    const K: f64 = 40.0 * 20.0 * 20.0 * std::f64::consts::PI / (0.3 * 35.0 * 1000.0 * 50.0);

    #[test]
    fn a_steady_infeed_settles_at_its_depth_with_the_deflection_k_times_it() {
        let model = StockModel::default();
        let mut stock = Stock::new(0.2);
        // 10 rev at 0.015 mm/rev from 0.2 down to 0.05 above the finished surface.
        stock.grind(&model, &round(), &pass(0.2, -0.15, 10.0), 0);
        let f = 0.015;
        // Before a pass the stock stands e above the command, e_{n+1} = e_n·K/(1+K) + f,
        // which settles at f·(1+K): the depth cut settles at f, the wheel stands δ = K·f off
        // and leaves the stock K·f above the command of its last pass (a spiral: 0.05 mm at
        // the last degree, f more one revolution earlier).
        for (j, (s, d)) in stock.stock_mm.iter().zip(&stock.deflection_mm).enumerate() {
            let last_command = 0.05 + f * (1.0 - (j + 1) as f64 / 360.0);
            assert!((d - K * f).abs() < 1e-9, "deflection {d} vs {}", K * f);
            assert!(
                (s - (last_command + K * f)).abs() < 1e-9,
                "stock {s} at {j}"
            );
        }
    }

    #[test]
    fn spark_out_decays_the_excess_by_k_over_one_plus_k_per_revolution() {
        let model = StockModel::default();
        let mut stock = Stock::new(0.2);
        stock.grind(&model, &round(), &pass(0.2, -0.2, 10.0), 0);
        let before = stock.stock_mm.clone();
        stock.grind(&model, &round(), &pass(0.0, 0.0, 2.0), 0);
        for j in [0, 100, 359] {
            let want = before[j] * (K / (1.0 + K)).powi(2);
            assert!(
                (stock.stock_mm[j] - want).abs() < 1e-12,
                "{} vs {want}",
                stock.stock_mm[j]
            );
        }
        // Where the infeed ended (359°) only the deflection K·f was left: 0.015 µm after two
        // revolutions; where it began, the spiral's f as well: 0.16 µm.
        assert!(stock.stock_mm[359] < 0.02e-3 && stock.stock_mm[0] < 0.17e-3);
    }

    #[test]
    fn the_errors_rebuild_the_stock_from_its_harmonics() {
        let mut stock = Stock::new(0.0);
        for (j, s) in stock.stock_mm.iter_mut().enumerate() {
            let c = (j as f64).to_radians();
            *s = 0.003 + 0.002 * (2.0 * c + 0.5).cos();
        }
        let e = stock.as_errors(10);
        assert!((e.size_um - 3.0).abs() < 1e-9);
        let h2 = &e.harmonics[1];
        assert!(
            (h2.amplitude_um - 2.0).abs() < 1e-9
                && (h2.phase_deg - 0.5f64.to_degrees()).abs() < 1e-6
        );
        assert!(
            e.harmonics
                .iter()
                .filter(|h| h.order != 2)
                .all(|h| h.amplitude_um < 1e-9)
        );
    }

    #[test]
    fn a_bad_setting_is_named() {
        let model = StockModel {
            force_ratio: 0.0,
            ..StockModel::default()
        };
        assert_eq!(
            model.problems(),
            ["stock.force_ratio = 0: must be a finite number > 0"]
        );
    }
}
