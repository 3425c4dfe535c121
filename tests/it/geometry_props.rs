//! Property tests of the wheel-head table over random valid cams (all three followers):
//! bounds every envelope must respect, exactness on the base circle and at a symmetric nose,
//! a uniform increasing c grid, and spot checks against the independent oracle.

use crate::support;

use camloop::core::geometry::{CamGeometry, Follower, Part};
use camloop::core::lift::{LiftCurve, LiftTable};
use proptest::prelude::*;
use proptest::test_runner::FileFailurePersistence;
use support::lobes::{
    PolyLobe, flat_min_radius_mm, knife_min_curvature_per_mm, roller_pitch_curvature_range_per_mm,
};
use support::oracle::{CamOracle, OracleFollower};

/// The accuracy requirement, mm: the library's d may differ from the exact envelope of the
/// smooth lift by this much (interpolating the 1° table), so bounds that hold exactly for the
/// smooth lift are checked to it.
const REQUIRED_MM: f64 = 1e-4;

/// Where the table must be exact (base circle, symmetric nose), mm: rounding plus the
/// library's root-search tolerance.
const EXACT_MM: f64 = 1e-9;

/// A random cam before validation.
#[derive(Debug, Clone)]
struct Draw {
    follower: usize,
    base_radius_mm: f64,
    wheel_radius_mm: f64,
    roller_radius_mm: f64,
    lobe: PolyLobe,
}

impl Draw {
    fn follower(&self) -> Follower {
        match self.follower {
            0 => Follower::Flat,
            1 => Follower::Roller {
                radius_mm: self.roller_radius_mm,
            },
            _ => Follower::Knife,
        }
    }

    fn oracle_follower(&self) -> OracleFollower {
        match self.follower {
            0 => OracleFollower::Flat,
            1 => OracleFollower::Roller {
                radius_mm: self.roller_radius_mm,
            },
            _ => OracleFollower::Knife,
        }
    }

    /// Valid for its follower with margin: flat ρ ≥ 1 mm; roller pitch curvature below
    /// 0.7/r (no undercut) and concave cam radius ≥ 2·R; knife concave radius ≥ 2·R.
    fn is_valid(&self) -> bool {
        let lift = |psi| self.lobe.lift_at_rad(psi);
        let (rb, wheel) = (self.base_radius_mm, self.wheel_radius_mm);
        match self.follower {
            0 => flat_min_radius_mm(lift, rb) >= 1.0,
            1 => {
                let r = self.roller_radius_mm;
                let (k_min, k_max) = roller_pitch_curvature_range_per_mm(lift, rb, r);
                k_max <= 0.7 / r && k_min >= -1.0 / (2.0 * wheel - r)
            }
            _ => knife_min_curvature_per_mm(lift, rb) >= -0.5 / wheel,
        }
    }

    /// The same cam with the lift scaled down until it is valid (a base circle always is).
    fn made_valid(mut self) -> Self {
        for _ in 0..40 {
            if self.is_valid() {
                return self;
            }
            self.lobe.lift_mm *= 0.85;
        }
        panic!("no valid lift found for {self:?}");
    }

    fn part(&self) -> Part {
        let (angles, lifts) = self.lobe.table_1deg();
        let table = LiftTable::from_points(angles, lifts, "proptest lobe").expect("valid table");
        Part::cam(
            CamGeometry {
                base_radius_mm: self.base_radius_mm,
                follower: self.follower(),
                wheel_radius_mm: self.wheel_radius_mm,
            },
            LiftCurve::new(&table),
        )
        .unwrap_or_else(|e| panic!("valid cam refused: {e} ({self:?})"))
    }

    /// Whether a wheel touching the base circle at `c_deg` clears the whole lobe with room to
    /// spare, and c is more than 15° from any lift, so that the spline's ringing (it decays by
    /// 2 − √3 per knot away from the lobe) is below 1e-12 mm there: then d = Rb + R exactly.
    ///
    /// A point at radius ρ, angle θ is outside the wheel centred at (Rb + R)·u(c) when
    /// ρ² + Rb² + 2·Rb·R − 2ρ·(Rb + R)·cos(θ − c) ≥ 0; the lobe's outline radius is at most
    /// Rb + h(θ) for every follower, and the left side decreases in ρ over that range.
    fn wheel_on_base_circle_only(&self, c_deg: f64) -> bool {
        let (rb, wheel) = (self.base_radius_mm, self.wheel_radius_mm);
        let near_lobe = (-15..=15).any(|j| !self.lobe.on_base_circle(c_deg + f64::from(j)));
        if near_lobe {
            return false;
        }
        (0..3600).all(|i| {
            let theta_deg = f64::from(i) * 0.1;
            if self.lobe.on_base_circle(theta_deg) {
                return true; // inside the circle the wheel rests on
            }
            // 1 µm of room for the spline's departure from the smooth lift.
            let rho = rb + self.lobe.lift_at_deg(theta_deg) + 1e-3;
            let cos_d = (theta_deg - c_deg).to_radians().cos();
            rho * rho + rb * rb + 2.0 * rb * wheel - 2.0 * rho * (rb + wheel) * cos_d >= 0.0
        })
    }
}

/// `cases` random cases; failures are kept next to this file (tests/ has no lib.rs for
/// proptest's default layout to anchor on).
fn config(cases: u32) -> ProptestConfig {
    ProptestConfig {
        cases,
        failure_persistence: Some(Box::new(FileFailurePersistence::WithSource(
            "proptest-regressions",
        ))),
        ..ProptestConfig::default()
    }
}

prop_compose! {
    fn valid_cam(symmetric: bool)(
        follower in 0usize..3,
        base_radius_mm in 18.0..35.0f64,
        wheel_radius_mm in 150.0..400.0f64,
        roller_radius_mm in 6.0..14.0f64,
        lift_mm in 2.0..10.0f64,
        nose_deg in 0u16..360,
        nose_frac in 0.0..1.0f64,
        rise_deg in 70u16..100,
        return_deg in 70u16..100,
        nose_accel in 2.0..8.0f64,
    ) -> Draw {
        let lobe = PolyLobe {
            lift_mm,
            nose_deg: f64::from(nose_deg) + if symmetric { 0.0 } else { nose_frac },
            rise_deg: f64::from(rise_deg),
            return_deg: f64::from(if symmetric { rise_deg } else { return_deg }),
            // P's x⁴ coefficient is 35 − 2.5·a: above a = 14 the lift dips below zero next to
            // the base circle, which no cam has. The return's a grows with (β_return/β_rise)²,
            // so a is capped to keep both sides' at most 13.
            nose_accel: nose_accel.min(13.0 * (f64::from(rise_deg) / f64::from(if symmetric { rise_deg } else { return_deg })).powi(2)),
        };
        Draw { follower, base_radius_mm, wheel_radius_mm, roller_radius_mm, lobe }.made_valid()
    }
}

proptest! {
    // Each case builds a part and scans its 360-point table (and the oracle, below), which is
    // costly in a debug build: a small number of cases, spread over all three followers.
    #![proptest_config(config(24))]

    #[test]
    fn table_is_uniform_bounded_and_exact_on_the_base_circle(cam in valid_cam(false)) {
        let part = cam.part();
        let (rb, wheel) = (cam.base_radius_mm, cam.wheel_radius_mm);
        let table = part.wheel_table(360).expect("table of a valid part");
        prop_assert_eq!(table.len(), 360);
        let mut on_base = 0;
        for (k, p) in table.iter().enumerate() {
            // c grid: k·1°, to rounding, strictly increasing.
            prop_assert!((p.c_deg - k as f64).abs() <= 1e-12, "c[{}] = {}", k, p.c_deg);
            if k > 0 {
                prop_assert!(p.c_deg > table[k - 1].c_deg);
            }
            // h ≥ 0 puts the base disc inside the part for every follower (flat: every face
            // is ≥ Rb out; roller: every disc stays outside radius Rb; knife: r = Rb + h), and
            // r ≤ Rb + max h keeps the part inside that circle.
            prop_assert!(p.d_mm >= rb + wheel - REQUIRED_MM, "d = {} below Rb + R at {}°", p.d_mm, p.c_deg);
            prop_assert!(
                p.d_mm <= rb + cam.lobe.lift_mm + wheel + REQUIRED_MM,
                "d = {} above Rb + L + R at {}°", p.d_mm, p.c_deg
            );
            if cam.wheel_on_base_circle_only(p.c_deg) {
                on_base += 1;
                prop_assert!(
                    (p.d_mm - (rb + wheel)).abs() <= EXACT_MM,
                    "base circle at {}°: d = {}, Rb + R = {}", p.c_deg, p.d_mm, rb + wheel
                );
            }
        }
        // The lobe spans at most 200°: a base-circle region must exist, or the check above
        // tested nothing.
        prop_assert!(on_base >= 60, "only {} base-circle points", on_base);
    }

    #[test]
    fn symmetric_lobe_reaches_base_plus_lift_plus_wheel_at_the_nose(cam in valid_cam(true)) {
        // A lobe symmetric about a knot gives a spline symmetric about it with its maximum L
        // there, and the wheel then touches the nose on the symmetry axis for every follower.
        let part = cam.part();
        let d = part.d_at_c_deg(cam.lobe.nose_deg).expect("d at the nose");
        let expected = cam.base_radius_mm + cam.lobe.lift_mm + cam.wheel_radius_mm;
        prop_assert!((d - expected).abs() <= EXACT_MM, "nose: d = {}, Rb + L + R = {}", d, expected);
    }
}

proptest! {
    // The oracle builds a 7200-point outline per case (~0.3 s in a debug build).
    #![proptest_config(config(12))]

    #[test]
    fn random_cams_match_the_oracle(
        cam in valid_cam(false),
        c_offsets in proptest::collection::vec(0.0..360.0f64, 6),
    ) {
        let part = cam.part();
        let lobe = cam.lobe;
        let oracle = CamOracle::new(
            |psi| lobe.lift_at_rad(psi),
            cam.base_radius_mm,
            cam.oracle_follower(),
            cam.wheel_radius_mm,
        );
        // Six random angles plus both flanks' mid-points, where d changes fastest.
        let mut cs = c_offsets;
        cs.push(lobe.nose_deg - lobe.rise_deg / 2.0);
        cs.push(lobe.nose_deg + lobe.return_deg / 2.0);
        for c in cs {
            let c = c.rem_euclid(360.0);
            let d = part.d_at_c_deg(c).expect("d of a valid part");
            let exact = oracle.d_mm(c);
            prop_assert!(
                (d - exact).abs() <= REQUIRED_MM,
                "c = {}°: library {} mm, oracle {} mm ({:?})", c, d, exact, cam
            );
        }
    }
}
