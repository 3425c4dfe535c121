//! The demo intake lobe and its speed plan under the demo camshaft's limits
//! (`config/parts/demo-camshaft.toml`), shared by the simulated control's and grinder's
//! tests of the plan.

#![allow(dead_code)]

use camloop_core::geometry::{CamGeometry, Follower, Part};
use camloop_core::lift::{LiftCurve, LiftTable};
use camloop_core::speed_plan::tables::{VaTables, va_tables};
use camloop_core::speed_plan::{self, SpeedLimits, SpeedPlan};

const INTAKE: &str = include_str!("../../../../config/parts/demo-intake-lobe.csv");

/// The demo camshaft's geometry: a 20 mm base circle, a flat follower, a 250 mm wheel.
pub fn geometry() -> CamGeometry {
    CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: 250.0,
    }
}

/// The demo intake lobe.
pub fn part() -> Part {
    let table = LiftTable::parse_csv(INTAKE, "demo lobe").unwrap();
    Part::cam(geometry(), LiftCurve::new(&table)).unwrap()
}

/// The plan of `part` under the demo camshaft's limits.
pub fn plan(part: &Part) -> SpeedPlan {
    let limits = SpeedLimits {
        x_velocity_mm_s: 200.0,
        x_acceleration_mm_s2: 10_000.0,
        x_jerk_mm_s3: 10_000_000.0,
        c_max_speed_rpm: 120.0,
        c_max_accel_deg_s2: 3600.0,
        q_w_max_mm3_mm_s: 2.36,
        stock_mm: 0.02,
    };
    speed_plan::plan(part, &limits).unwrap()
}

/// The demo lobe's plan tables, 0.1° of VA apart.
pub fn tables() -> VaTables {
    let part = part();
    va_tables(&part, &plan(&part).law, 0.1).unwrap()
}
