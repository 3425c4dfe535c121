//! The speed plan against independent methods: the phase-plane passes against a linear
//! program on the same discrete problem, and every limit of the finished plan recomputed
//! at every 0.1° by finite differences of the exact geometry in time.

use camloop_core::geometry::{CamGeometry, CrankpinGeometry, Follower, Part};
use camloop_core::lift::{LiftCurve, LiftTable};
use camloop_core::speed_plan::{
    self, Constraint, ProfileSamples, SpeedLimits, SpeedPlan, SpeedPlanError, TimeLaw, topp,
};
use microlp::{ComparisonOp, OptimizationDirection, Problem};

const INTAKE: &str = include_str!("../../../config/parts/demo-intake-lobe.csv");
const EXHAUST: &str = include_str!("../../../config/parts/demo-exhaust-lobe.csv");

fn lobe(text: &str) -> Part {
    let table = LiftTable::parse_csv(text, "demo lobe").unwrap();
    let geometry = CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: 250.0,
    };
    Part::cam(geometry, LiftCurve::new(&table)).unwrap()
}

fn roller_lobe(text: &str) -> Part {
    let table = LiftTable::parse_csv(text, "demo lobe").unwrap();
    let geometry = CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Roller { radius_mm: 12.0 },
        wheel_radius_mm: 250.0,
    };
    Part::cam(geometry, LiftCurve::new(&table)).unwrap()
}

fn pin() -> Part {
    Part::crankpin(CrankpinGeometry {
        throw_mm: 45.0,
        pin_radius_mm: 27.0,
        wheel_radius_mm: 300.0,
    })
    .unwrap()
}

/// The demo camshaft's limits (config/parts/demo-camshaft.toml).
fn demo_limits() -> SpeedLimits {
    SpeedLimits {
        x_velocity_mm_s: 200.0,
        x_acceleration_mm_s2: 10_000.0,
        x_jerk_mm_s3: 10_000_000.0,
        c_max_speed_rpm: 120.0,
        c_max_accel_deg_s2: 3600.0,
        q_w_max_mm3_mm_s: 2.36,
        stock_mm: 0.02,
    }
}

/// Limits under which the X axis binds too (slow X, generous removal), so the linear
/// program meets every kind of constraint.
fn x_bound_limits() -> SpeedLimits {
    SpeedLimits {
        x_velocity_mm_s: 60.0,
        x_acceleration_mm_s2: 800.0,
        x_jerk_mm_s3: 200_000.0,
        q_w_max_mm3_mm_s: 20.0,
        ..demo_limits()
    }
}

/// The same discrete problem as a linear program: maximise Σ b_i subject to every node's
/// bounds, written here from the problem's coefficients. For these constraints the feasible
/// profiles are closed under the pointwise maximum, so the greatest one (the passes' answer)
/// is the LP optimum for any positive weights.
fn lp_profile(problem: &topp::PhaseProblem) -> Vec<f64> {
    let n = problem.nodes.len();
    let two_step = 2.0 * problem.step_rad;
    let mut lp = Problem::new(OptimizationDirection::Maximize);
    let b: Vec<_> = problem
        .nodes
        .iter()
        .map(|node| lp.add_var(1.0, (0.0, node.b_max)))
        .collect();
    for (i, node) in problem.nodes.iter().enumerate() {
        let j = (i + 1) % n;
        // α_i = (b_j − b_i)/(2Δ): |α_i| ≤ c_accel_max.
        let alpha = [(b[j], 1.0 / two_step), (b[i], -1.0 / two_step)];
        lp.add_constraint(alpha, ComparisonOp::Le, node.c_accel_max);
        lp.add_constraint(alpha, ComparisonOp::Ge, -node.c_accel_max);
        // X acceleration x2·b_i + x1·α_i within ±a.
        let x_accel = [
            (b[i], node.x2 - node.x1 / two_step),
            (b[j], node.x1 / two_step),
        ];
        lp.add_constraint(x_accel, ComparisonOp::Le, node.x_accel_max);
        lp.add_constraint(x_accel, ComparisonOp::Ge, -node.x_accel_max);
    }
    let solution = match lp.solve().expect("the LP is feasible: a constant speed is") {
        microlp::SolveOutcome::Solution(s) => s,
        other => panic!("LP not solved: {other:?}"),
    };
    b.iter().map(|&v| solution.var_value(v)).collect()
}

/// Every constraint of the discrete problem, checked on a profile from its coefficients, to
/// 1e-9 of the bound (rounding only).
fn assert_feasible(name: &str, problem: &topp::PhaseProblem, b: &[f64]) {
    let n = b.len();
    for (i, node) in problem.nodes.iter().enumerate() {
        let alpha = (b[(i + 1) % n] - b[i]) / (2.0 * problem.step_rad);
        let x_accel = node.x2 * b[i] + node.x1 * alpha;
        assert!(
            b[i] >= 0.0 && b[i] <= node.b_max * (1.0 + 1e-9),
            "{name} node {i}"
        );
        assert!(
            alpha.abs() <= node.c_accel_max * (1.0 + 1e-9),
            "{name} node {i}: α {alpha}"
        );
        assert!(
            x_accel.abs() <= node.x_accel_max * (1.0 + 1e-9),
            "{name} node {i}: {x_accel}"
        );
    }
}

/// On a 5° grid (72 nodes) the passes' profile keeps every constraint, and its revolution
/// time is never longer than the LP's. With the demo's limits the two agree on every node to
/// 1e-6 of the largest b (the LP's feasibility tolerance is about 1e-9 relative; the passes
/// stop at 1e-13). Where the X acceleration binds near dX/dC = 0, the reach of a step falls
/// as b rises (slope 1 − 2Δ·X″/X′ < 0 at this coarse step), the feasible profiles are no longer
/// closed under the maximum, and Σb (the LP's objective) and time part ways a little: the LP
/// then trades speed between neighbours and the times differ by at most 1e-4 relative.
#[test]
fn phase_plane_passes_match_a_linear_program_on_a_coarse_grid() {
    for (name, part, limits, exact) in [
        ("intake, demo limits", lobe(INTAKE), demo_limits(), true),
        ("exhaust, demo limits", lobe(EXHAUST), demo_limits(), true),
        ("intake, X bound", lobe(INTAKE), x_bound_limits(), false),
        ("exhaust, X bound", lobe(EXHAUST), x_bound_limits(), false),
        ("crankpin, X bound", pin(), x_bound_limits(), false),
    ] {
        let samples = ProfileSamples::new(&part).unwrap();
        let n = samples.samples.len();
        let problem = speed_plan::phase_problem(
            &samples,
            &limits,
            &vec![f64::INFINITY; n],
            &vec![1.0; n],
            50,
        );
        assert_eq!(problem.nodes.len(), 72);
        let passes = topp::time_optimal_profile(&problem);
        let lp = lp_profile(&problem);
        let scale = passes.iter().fold(0.0f64, |m, &v| m.max(v));
        assert_feasible(name, &problem, &passes);
        let (t_passes, t_lp) = (
            topp::revolution_time_s(problem.step_rad, &passes),
            topp::revolution_time_s(problem.step_rad, &lp),
        );
        assert!(
            t_passes <= t_lp * (1.0 + 1e-9),
            "{name}: {t_passes} s vs {t_lp} s"
        );
        assert!(
            t_lp <= t_passes * (1.0 + 1e-4),
            "{name}: {t_passes} s vs {t_lp} s"
        );
        if exact {
            let worst = passes
                .iter()
                .zip(&lp)
                .map(|(p, l)| (p - l).abs())
                .fold(0.0, f64::max);
            assert!(
                worst <= 1e-6 * scale,
                "{name}: b differs by {worst} of {scale}"
            );
        }
        // The problem is not trivial: some node sits below its velocity limit.
        let below = passes
            .iter()
            .zip(&problem.nodes)
            .filter(|(b, node)| **b < 0.99 * node.b_max)
            .count();
        assert!(below > 0, "{name}: the acceleration limits never acted");
    }
}

/// Every limit's usage at C = `c_deg` along `law`, recomputed from the exact geometry by
/// finite differences in time: X(t) = d(C(t)) − x_zero with 5-point stencils at steps of
/// 10 µs (truncation ~h²·X⁽⁵⁾ and rounding ~1e-13 mm/h³ both below 1e-3 of the limits
/// here), the jerk from one-sided stencils on both sides (it steps at the lift's knots), C's speed and acceleration the same way, and Q′w from the contact point's speed
/// and the curvature of the circle through three contact points 1 ms apart.
fn independent_usage(part: &Part, limits: &SpeedLimits, law: &TimeLaw, c_deg: f64) -> [f64; 6] {
    let t = law.time_at(c_deg);
    let c0 = law.at(t).c_rad.to_degrees();
    let off = (c0 - c_deg + 180.0).rem_euclid(360.0) - 180.0;
    assert!(off.abs() < 1e-9, "time_at({c_deg}) lands at {c0}");
    let h = 1e-5;
    let c_at = |k: f64| law.at(t + k * h).c_rad;
    let x_at = |k: f64| part.d_at_c_deg(c_at(k).to_degrees()).unwrap() - part.x_zero_mm();
    let d5 = |f: &dyn Fn(f64) -> f64| {
        let (m2, m1, z, p1, p2) = (f(-2.0), f(-1.0), f(0.0), f(1.0), f(2.0));
        (
            (8.0 * (p1 - m1) - (p2 - m2)) / (12.0 * h),
            (p1 - 2.0 * z + m1) / (h * h),
            (p2 - 2.0 * p1 + 2.0 * m1 - m2) / (2.0 * h * h * h),
        )
    };
    let (xv, xa, _) = d5(&x_at);
    // Steps of 0.01° of C, so a one-sided stencil sees 0.03° (a jerk step further off stays
    // out). Third differences amplify rounding by 8/h³: d is exact to about 1e-13 mm, which
    // costs below 300 mm/s³ here (3e-5 of the demo limit, 1.5e-3 of the X-bound one).
    let hj = 0.01f64.to_radians() / law.at(t).omega_rad_s;
    let x_at_t = |dt: f64| part.d_at_c_deg(law.at(t + dt).c_rad.to_degrees()).unwrap();
    let one_sided = |s: f64| {
        let x = |k: f64| x_at_t(k * s * hj);
        (x(3.0) - 3.0 * x(2.0) + 3.0 * x(1.0) - x(0.0)) * s / (hj * hj * hj)
    };
    let xj = one_sided(1.0).abs().max(one_sided(-1.0).abs());
    let (cv, ca, _) = d5(&c_at);
    let contact = |dt: f64| {
        part.contact_at_c_deg(law.at(t + dt).c_rad.to_degrees())
            .unwrap()
            .1
    };
    let (pm, pp) = (contact(-h), contact(h));
    let surface_speed = (pp[0] - pm[0]).hypot(pp[1] - pm[1]) / (2.0 * h);
    let (a, b, c) = (contact(-1e-3), contact(0.0), contact(1e-3));
    let cross = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    let dist = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]);
    let kappa = 2.0 * cross / (dist(a, b) * dist(b, c) * dist(a, c));
    let q_w = limits.stock_mm * (1.0 + 0.5 * limits.stock_mm * kappa) * surface_speed;
    [
        xv.abs() / limits.x_velocity_mm_s,
        xa.abs() / limits.x_acceleration_mm_s2,
        xj.abs() / limits.x_jerk_mm_s3,
        cv / speed_plan::rad_s(limits.c_max_speed_rpm),
        ca.abs() / limits.c_max_accel_deg_s2.to_radians(),
        q_w / limits.q_w_max_mm3_mm_s,
    ]
}

/// Checks `plan` at every 0.1°: the independent usage never exceeds 1, and agrees with the
/// planner's own to 1e-3 of each limit; 3e-3 for X acceleration, because the planner's X″ is
/// a central difference over ±0.05°, which averages across the lift table's knots where the
/// lift's third derivative steps. X jerk steps there, and also where C's jerk steps (at the
/// time law's knots, every 0.3° to 1.2° of C): both sides are taken here (one-sided
/// stencils) and the larger counts, while the planner evaluates each side at the grid angles
/// within it. So the independent jerk is compared with the planner's largest within ±0.3°,
/// and may exceed it by 1e-2 at most: between grid angles the jerk moves with X′, X″, X‴ by
/// up to about 1 % of the limit here, which is why the planner accepts at most 98 % of the
/// jerk limit at its grid angles. The planner's margins (0.5 % on speeds, removal and
/// jerk, 2 % on accelerations) cover these differences.
fn check_every_tenth_degree(name: &str, part: &Part, limits: &SpeedLimits, plan: &SpeedPlan) {
    let n = plan.points.len();
    assert_eq!(n, 3600);
    for (i, p) in plan.points.iter().enumerate() {
        let usage = independent_usage(part, limits, &plan.law, p.c_deg);
        for c in Constraint::ALL {
            let (ours, theirs) = (usage[c as usize], p.usage[c as usize]);
            assert!(
                ours <= 1.0,
                "{name}: {} at {:.1}°: {ours}",
                c.name(),
                p.c_deg
            );
            let agrees = match c {
                Constraint::XJerk => {
                    let near = (0..7)
                        .map(|d| plan.points[(i + n + d - 3) % n].usage[c as usize])
                        .fold(0.0, f64::max);
                    ours - near <= 1e-2
                }
                Constraint::XAcceleration => (ours - theirs).abs() <= 3e-3,
                _ => (ours - theirs).abs() <= 1e-3,
            };
            assert!(
                agrees,
                "{name}: {} at {:.1}°: planner {theirs} vs independent {ours}",
                c.name(),
                p.c_deg
            );
        }
    }
}

#[test]
fn every_limit_holds_at_every_tenth_of_a_degree() {
    for (name, part, limits) in [
        ("intake", lobe(INTAKE), demo_limits()),
        ("exhaust", lobe(EXHAUST), demo_limits()),
        ("intake, X bound", lobe(INTAKE), x_bound_limits()),
        (
            "intake, roller follower",
            roller_lobe(INTAKE),
            demo_limits(),
        ),
        (
            "crankpin",
            pin(),
            SpeedLimits {
                q_w_max_mm3_mm_s: 0.64,
                ..demo_limits()
            },
        ),
    ] {
        let plan = speed_plan::plan(&part, &limits).unwrap();
        assert!(!plan.is_constant, "{name}: no varying plan found");
        check_every_tenth_degree(name, &part, &limits, &plan);
        // It closes: C gains exactly one turn per period, at the same speed.
        let (start, end) = (plan.law.at(0.0), plan.law.at(plan.revolution_s()));
        assert!(
            (end.c_rad - start.c_rad - std::f64::consts::TAU).abs() < 1e-12,
            "{name}"
        );
        assert!((end.omega_rad_s - start.omega_rad_s).abs() < 1e-9, "{name}");
    }
}

/// The fastest constant speed, from the independent usage at 1 rad/s at every 0.1° (at a
/// constant speed each usage scales with a known power of ω: speeds and removal with ω,
/// X acceleration with ω², X jerk with ω³), is the planner's to 1e-4 relative (the
/// independent stencils' accuracy), and the same limit binds.
#[test]
fn fastest_constant_speed_matches_the_independent_usage() {
    let part = lobe(INTAKE);
    let limits = demo_limits();
    let plan = speed_plan::plan(&part, &limits).unwrap();
    let law = TimeLaw::constant(std::f64::consts::TAU, 360);
    let powers = [1.0, 2.0, 3.0, 1.0, 1.0, 1.0];
    let mut fastest = (f64::INFINITY, 0);
    for k in 0..3600 {
        let usage = independent_usage(&part, &limits, &law, k as f64 * 0.1);
        for (i, (u, p)) in usage.iter().zip(powers).enumerate() {
            let omega = (1.0 / u).powf(1.0 / p);
            if omega < fastest.0 {
                fastest = (omega, i);
            }
        }
    }
    let (planned, independent) = (plan.constant.speed_rpm, speed_plan::rpm(fastest.0));
    assert!(
        (planned - independent).abs() <= 1e-4 * independent,
        "{planned} vs {independent}"
    );
    assert_eq!(plan.constant.binding as usize, fastest.1);
    assert_eq!(plan.constant.binding, Constraint::RemovalRate);
}

/// The figures: the demo lobes' finish revolution is at least 25 % shorter than at
/// the fastest constant speed under the same limits; the demo's q_w_max makes that constant
/// speed the demo's 30 rpm on the intake lobe.
#[test]
fn demo_lobes_grind_at_least_a_quarter_faster() {
    for (name, text) in [("intake", INTAKE), ("exhaust", EXHAUST)] {
        let plan = speed_plan::plan(&lobe(text), &demo_limits()).unwrap();
        assert!(
            plan.time_saved() >= 0.25,
            "{name}: {:.3}",
            plan.time_saved()
        );
    }
    let intake = speed_plan::plan(&lobe(INTAKE), &demo_limits()).unwrap();
    assert!(
        (intake.constant.speed_rpm - 30.0).abs() < 0.1,
        "{}",
        intake.constant.speed_rpm
    );
}

#[test]
fn bad_limits_are_named() {
    let limits = SpeedLimits {
        c_max_accel_deg_s2: f64::NAN,
        ..demo_limits()
    };
    match speed_plan::plan(&lobe(INTAKE), &limits) {
        Err(SpeedPlanError::InvalidLimit { name, .. }) => assert_eq!(name, "c_max_accel_deg_s2"),
        other => panic!("{other:?}"),
    }
}

/// The tables the control is to run: C = f(VA) reproduces the time law to 1e-9° (it is the
/// law's own cubics, rounding only), the X table stays within 0.1 µm of the exact X(C(VA))
/// between its points, and its own motion at VA's constant speed (exact for its cubics)
/// keeps the X limits.
#[test]
fn the_virtual_axis_tables_run_the_plan() {
    let part = lobe(INTAKE);
    let limits = demo_limits();
    let plan = speed_plan::plan(&part, &limits).unwrap();
    let tables = speed_plan::tables::va_tables(&part, &plan.law, 0.1).unwrap();
    // One segment per piece of the law: no piece shorter than the demo's C acceleration
    // limit allows (2.8 ms, see `shortest_piece_s`), and a count whose VA knots are exact.
    let pieces = plan.law.pieces();
    assert_eq!(tables.c_segments.len(), pieces);
    assert!(plan.revolution_s() / pieces as f64 >= speed_plan::shortest_piece_s(&limits));
    assert_eq!(3_600_000 % pieces, 0);
    for (k, s) in tables.c_segments.iter().enumerate() {
        let u = 0.37;
        let table_c = s.x0_mm + u * (s.a1_mm + u * (s.a2_mm + u * s.a3_mm));
        let t = (k as f64 + u) / pieces as f64 * plan.revolution_s();
        let law_c = plan.law.at(t).c_rad.to_degrees();
        assert!(
            (table_c - law_c).abs() < 1e-9,
            "piece {k}: {table_c} vs {law_c}"
        );
    }
    assert!(tables.x_deviation_um <= 0.1, "{}", tables.x_deviation_um);
    let motion = camloop_core::fit::poly_motion(&tables.x_segments, tables.va_speed_rpm);
    assert!(motion.velocity_max_mm_s <= limits.x_velocity_mm_s);
    assert!(motion.acceleration_max_mm_s2.unwrap() <= limits.x_acceleration_mm_s2);
    assert!(motion.jerk_max_mm_s3.unwrap() <= limits.x_jerk_mm_s3);
    // The table's X motion is the plan's to within what 0.1 µm of shape allows.
    let planned_v = plan.max_usage(Constraint::XVelocity) * limits.x_velocity_mm_s;
    assert!((motion.velocity_max_mm_s - planned_v).abs() <= 0.01 * planned_v);
}

/// The table program as written: both CTABDEFs read back (by the program reader) with the
/// numbers the program returns, and the POLY blocks, rebuilt from the text alone, give C
/// within 1e-3° of the plan and X within 0.2 µm of the exact X(C(VA)) at every segment's
/// middle (0.1 µm of table deviation plus rounding to 4 decimals).
#[test]
fn the_table_program_text_holds_the_plan() {
    use camloop_core::program::parse_ctabdef;
    use camloop_core::speed_plan::render::{VaProgramSettings, render_va_table_program};
    let part = lobe(INTAKE);
    let plan = speed_plan::plan(&part, &demo_limits()).unwrap();
    let tables = speed_plan::tables::va_tables(&part, &plan.law, 0.1).unwrap();
    let settings = VaProgramSettings {
        name: "DEMO_CAM_IN1_PLAN".into(),
        virtual_axis: "VA".into(),
        x_axis: "X".into(),
        c_axis: "C".into(),
        x_decimals: 4,
        c_decimals: 4,
        x_table: 1,
        c_table: 17,
        ..VaProgramSettings::default()
    };
    let text = render_va_table_program(&tables, &settings).unwrap();
    assert!(
        text.contains("CL_TNO=1 ") && text.contains("CL_TNO_C=17 "),
        "{text}"
    );
    let mut defs = Vec::new();
    let mut blocks: Vec<Vec<(f64, f64, f64, f64)>> = Vec::new();
    let mut start = (0.0, 0.0);
    let num = |s: &str| s.trim().parse::<f64>().unwrap();
    for (i, line) in text.lines().enumerate() {
        if line.starts_with("CTABDEF(") {
            defs.push(parse_ctabdef(line, i + 1).unwrap());
            blocks.push(Vec::new());
        } else if let Some(rest) = line.strip_prefix("G1 VA=") {
            let (va, value) = rest.split_once(' ').unwrap();
            start = (num(va), num(value.split_once('=').unwrap().1));
        } else if let Some(rest) = line.strip_prefix("PO[VA]=(") {
            let (va, rest) = rest.split_once(") PO[").unwrap();
            let inner = rest.split_once("=(").unwrap().1.trim_end_matches(')');
            let v: Vec<f64> = inner.split(',').map(num).collect();
            let block = blocks.last_mut().unwrap();
            let (va0, x0) = block.last().map_or(start, |b| (b.0, b.1));
            block.push((num(va), v[0], v[1], v[2]));
            let (va1, x1, a2, a3) = (num(va), v[0], v[1], v[2]);
            let a1 = x1 - x0 - a2 - a3;
            let mid = x0 + 0.5 * a1 + 0.25 * a2 + 0.125 * a3;
            let va_mid = 0.5 * (va0 + va1);
            let c_deg = plan
                .law
                .at(va_mid / 360.0 * plan.revolution_s())
                .c_rad
                .to_degrees();
            if defs.len() == 1 {
                let exact = part.d_at_c_deg(c_deg.rem_euclid(360.0)).unwrap() - part.x_zero_mm();
                assert!(
                    (mid - exact).abs() < 2e-4,
                    "X at VA {va_mid}: {mid} vs {exact}"
                );
            } else {
                assert!(
                    (mid - c_deg).abs() < 1e-3,
                    "C at VA {va_mid}: {mid} vs {c_deg}"
                );
            }
        }
    }
    let numbers: Vec<(String, String, u32, String)> = defs
        .into_iter()
        .map(|d| (d.following, d.leading, d.number, d.periodicity))
        .collect();
    assert_eq!(
        numbers,
        [
            ("X".into(), "VA".into(), 1, "1".into()),
            ("C".into(), "VA".into(), 17, "2".into())
        ]
    );
    assert_eq!(blocks[1].len(), plan.law.pieces());
    assert!((blocks[1].last().unwrap().0 - 360.0).abs() < 1e-9);
}

/// The main program couples both tables by the numbers the table program returns, C first,
/// and turns VA at the plan's constant speed for the revolutions asked.
#[test]
fn the_main_program_couples_the_returned_numbers() {
    use camloop_core::speed_plan::render::{VaProgramSettings, render_va_main_program};
    let part = lobe(INTAKE);
    let plan = speed_plan::plan(&part, &demo_limits()).unwrap();
    let tables = speed_plan::tables::va_tables(&part, &plan.law, 0.1).unwrap();
    let settings = VaProgramSettings {
        name: "DEMO_CAM_IN1_PLAN".into(),
        virtual_axis: "VA".into(),
        x_axis: "X".into(),
        c_axis: "C".into(),
        x_decimals: 4,
        c_decimals: 4,
        x_table: 1,
        c_table: 2,
        ..VaProgramSettings::default()
    };
    let text =
        render_va_main_program("CAMLOOP_GRIND", &settings, tables.va_speed_rpm, 1.0).unwrap();
    let at = |needle: &str| {
        text.find(needle)
            .unwrap_or_else(|| panic!("{needle}: {text}"))
    };
    assert!(at("DEMO_CAM_IN1_PLAN(CL_TNO,CL_TNO_C)") < at("LEADON(C,VA,CL_TNO_C)"));
    assert!(at("LEADON(C,VA,CL_TNO_C)") < at("LEADON(X,VA,CL_TNO)"));
    assert!(at("LEADON(X,VA,CL_TNO)") < at("POS[VA]=IC(360.0000)"));
    // VA turns 360° per planned revolution: FA in degrees per minute.
    let fa = 360.0 * 60.0 / plan.revolution_s();
    assert!(text.contains(&format!("FA[VA]={fa:.3}")), "{fa:.3}: {text}");
    assert!(!text.contains("LEADON(X,VA,1)") && !text.contains("LEADON(C,VA,2)"));
}
