//! The corrected X table over the virtual axis re-checked against the X limits: the exact
//! per-segment maxima of the guard against finite differences of the written table sampled
//! in time (an independent path), the demo features' own tables accepted, and a correction
//! that makes X too steep refused with the angle named.

use camloop_core::compensate::{AxisLimits, GuardError};
use camloop_core::geometry::{CamGeometry, CrankpinGeometry, Follower, Part};
use camloop_core::lift::{LiftCurve, LiftTable};
use camloop_core::speed_plan::guard::{check_x_over_va, x_maxima};
use camloop_core::speed_plan::tables::{VaTables, va_tables};
use camloop_core::speed_plan::{self, SpeedPlanSettings};

const INTAKE: &str = include_str!("../../../config/parts/demo-intake-lobe.csv");
const EXHAUST: &str = include_str!("../../../config/parts/demo-exhaust-lobe.csv");

fn cam(table: &LiftTable) -> Part {
    let geometry = CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: 250.0,
    };
    Part::cam(geometry, LiftCurve::new(table)).unwrap()
}

fn pin() -> Part {
    Part::crankpin(CrankpinGeometry {
        throw_mm: 45.0,
        pin_radius_mm: 27.0,
        wheel_radius_mm: 300.0,
    })
    .unwrap()
}

fn tables_of(part: &Part) -> VaTables {
    let limits = SpeedPlanSettings::default().limits(&AxisLimits::default());
    let plan = speed_plan::plan(part, &limits).unwrap();
    assert!(!plan.is_constant);
    va_tables(part, &plan.law, 0.1).unwrap()
}

/// Largest |Ẋ|, |Ẍ|, |X⃛| of the X table sampled `samples` times a revolution in time, by
/// central differences of X(VA(t)) (step: `step` sampling intervals), each difference
/// taken only where its probes lie in one segment (a cubic's differences are exact there).
fn sampled_maxima(t: &VaTables, samples: usize, step: f64) -> ([f64; 3], [f64; 3]) {
    let period_s = 60.0 / t.va_speed_rpm;
    let x_at = |time_s: f64| {
        let va = (time_s / period_s * 360.0).rem_euclid(360.0);
        let k = t
            .x_segments
            .iter()
            .position(|s| va <= s.c_end_deg)
            .unwrap_or(t.x_segments.len() - 1);
        let s = &t.x_segments[k];
        let u = (va - s.c_start_deg) / (s.c_end_deg - s.c_start_deg);
        (k, s.x0_mm + u * (s.a1_mm + u * (s.a2_mm + u * s.a3_mm)))
    };
    let h = period_s / samples as f64;
    let d = step * h;
    let mut m = [0.0f64; 3];
    let mut x_max = 0.0f64;
    for i in 0..samples {
        let t0 = i as f64 * h;
        let p: Vec<(usize, f64)> = (-2..=2).map(|k| x_at(t0 + f64::from(k) * d)).collect();
        if p.iter().any(|q| q.0 != p[0].0) {
            continue;
        }
        let x = |k: usize| p[k].1;
        x_max = x_max.max(x(2).abs());
        let v = (x(3) - x(1)) / (2.0 * d);
        let a = (x(3) - 2.0 * x(2) + x(1)) / (d * d);
        let j = (x(4) - 2.0 * x(3) + 2.0 * x(1) - x(0)) / (2.0 * d * d * d);
        for (mi, value) in m.iter_mut().zip([v, a, j]) {
            *mi = mi.max(value.abs());
        }
    }
    // Rounding in the differences, of X and of VA (ε·360° times X's slope in VA): at most
    // 2e/(2d), 4e/d², 6e/(2d³) with e the rounding of one X.
    let slope_mm_deg = m[0] / (6.0 * t.va_speed_rpm);
    let e = f64::EPSILON * (x_max + 360.0 * slope_mm_deg);
    (m, [e / d, 4.0 * e / (d * d), 3.0 * e / (d * d * d)])
}

#[test]
fn the_guard_maxima_match_sampled_differences_and_the_demo_tables_pass() {
    let intake = LiftTable::parse_csv(INTAKE, "intake").unwrap();
    let exhaust = LiftTable::parse_csv(EXHAUST, "exhaust").unwrap();
    for (name, part) in [
        ("intake", cam(&intake)),
        ("exhaust", cam(&exhaust)),
        ("pin", pin()),
    ] {
        let t = tables_of(&part);
        check_x_over_va(&t, &AxisLimits::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let exact = x_maxima(&t);
        // 2·10⁵ samples a revolution: every segment is sampled many times, so the sampled
        // maxima come within 1 % of the exact ones (the differences of a cubic are exact
        // inside a segment; velocity and acceleration vary little between samples, the
        // jerk is constant), plus the rounding of X in the differences.
        let (fine, fine_rounding) = sampled_maxima(&t, 200_000, 1.0);
        // The jerk's third differences with a 10 times longer step (rounding 1000 times
        // smaller); the probes still lie in one segment nearly everywhere.
        let (coarse, coarse_rounding) = sampled_maxima(&t, 200_000, 10.0);
        let sampled = [fine[0], fine[1], coarse[2]];
        let rounding = [fine_rounding[0], fine_rounding[1], coarse_rounding[2]];
        for (i, what) in ["velocity", "acceleration", "jerk"].iter().enumerate() {
            println!(
                "{name}: max X {what} exact {:.4e} at VA {:.2}°, sampled {:.4e}",
                exact[i].0, exact[i].1, sampled[i]
            );
            assert!(
                sampled[i] <= exact[i].0 * 1.002 + rounding[i]
                    && sampled[i] >= exact[i].0 * 0.99 - rounding[i],
                "{name} {what}: exact {:?} sampled {}",
                exact[i],
                sampled[i]
            );
        }
    }
}

/// Limits under which the plan is bound by X acceleration on the flanks (removal generous).
fn x_bound() -> AxisLimits {
    AxisLimits {
        acceleration_mm_s2: 2_000.0,
        c_max_speed_rpm: 400.0,
        c_max_accel_deg_s2: 1e6,
        ..AxisLimits::default()
    }
}

#[test]
fn a_correction_too_steep_for_the_plan_is_refused_with_its_angle() {
    let nominal = LiftTable::parse_csv(INTAKE, "intake").unwrap();
    let part = cam(&nominal);
    let axis = x_bound();
    let settings = SpeedPlanSettings {
        q_w_max_mm3_mm_s: 1e3,
        ..SpeedPlanSettings::default()
    };
    let plan = speed_plan::plan(&part, &settings.limits(&axis)).unwrap();
    assert!(!plan.is_constant);
    let own = va_tables(&part, &plan.law, 0.1).unwrap();
    println!("nominal X maxima over VA {:?}", x_maxima(&own));
    check_x_over_va(&own, &axis).expect("the plan's own table keeps the limits");
    let at = x_maxima(&own)[1].1;
    let c_at = plan
        .law
        .at(at / 360.0 * plan.law.period_s())
        .c_rad
        .to_degrees();
    // A 5 µm bump (σ = 3°) where the plan uses X acceleration most: a correction the loop
    // could ask for, within the limits at 30 rpm, beyond them at the plan's speed there.
    let lifts: Vec<f64> = nominal
        .angles_deg()
        .iter()
        .zip(nominal.lifts_mm())
        .map(|(a, h)| h + 0.005 * (-((a - c_at) / 3.0).powi(2) / 2.0).exp())
        .collect();
    let bumped = LiftTable::from_points(nominal.angles_deg().to_vec(), lifts, "bumped").unwrap();
    let tables = va_tables(&cam(&bumped), &plan.law, 0.1).unwrap();
    println!(
        "corrected X maxima over VA {:?}, bump at C = {c_at:.2}",
        x_maxima(&tables)
    );
    let err = check_x_over_va(&tables, &axis).expect_err("the bump exceeds a limit");
    let text = err.to_string();
    println!("{text}");
    let GuardError::PlanMotion { c_deg, .. } = err else {
        panic!("{err:?}")
    };
    assert!((c_deg - c_at).abs() < 10.0, "{text}");
    assert!(text.contains("C = ") && text.contains("VA = "), "{text}");
}
