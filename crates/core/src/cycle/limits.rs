//! The cycle's checks against the part: each stage's removal rate Q′w (infeed per revolution
//! times the contact's surface speed, with the speed plan's own formula) and the X axis with
//! the infeed added (velocity, and the travel at approach and lift-off).

use super::{CycleSettings, ResolvedStage, StageKind, stage_key};
use crate::compensate::AxisLimits;
use crate::speed_plan::SpeedPlanSettings;
use crate::speed_plan::profile::{ProfileSamples, removal_per_arc_mm};
use std::f64::consts::TAU;

/// What a stage asks of the machine at its worst angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StageLoad {
    /// Largest specific removal rate, mm³/(mm·s), and the C angle where it is reached.
    pub q_w_mm3_mm_s: f64,
    pub q_w_at_c_deg: f64,
    /// Largest X velocity, coupled motion plus the infeed, mm/s.
    pub x_velocity_mm_s: f64,
}

/// The part and the recipe's limits a cycle is checked against.
#[derive(Debug, Clone, Copy)]
pub struct CycleContext<'a> {
    /// The finished part on the wheel the control believes, sampled as the plan samples it.
    pub samples: &'a ProfileSamples,
    pub axis: &'a AxisLimits,
    /// The recipe's `[speed_plan]` (its Q′w limit is the cycle's too).
    pub plan: &'a SpeedPlanSettings,
    /// `program.x_offset_mm`: added to every programmed X.
    pub x_offset_mm: f64,
}

/// The load of a stage run at constant `c_speed_rpm` with `infeed_per_rev_mm`: Q′w at each
/// angle is the speed plan's, `removal_per_arc(a, κ)·ds/dC·ω`, with the stage's infeed per
/// revolution as the stock `a` one revolution takes off.
pub fn stage_load(samples: &ProfileSamples, infeed_per_rev_mm: f64, c_speed_rpm: f64) -> StageLoad {
    let omega = c_speed_rpm * TAU / 60.0;
    let infeed_mm_s = infeed_per_rev_mm * c_speed_rpm / 60.0;
    let mut load = StageLoad {
        q_w_mm3_mm_s: 0.0,
        q_w_at_c_deg: 0.0,
        x_velocity_mm_s: 0.0,
    };
    for s in &samples.samples {
        let q =
            (removal_per_arc_mm(infeed_per_rev_mm, s.curvature_per_mm) * s.surface_mm_rad * omega)
                .abs();
        if q > load.q_w_mm3_mm_s {
            load.q_w_mm3_mm_s = q;
            load.q_w_at_c_deg = s.c_deg;
        }
        load.x_velocity_mm_s = load
            .x_velocity_mm_s
            .max((s.x1_mm_rad * omega).abs() + infeed_mm_s);
    }
    load
}

/// Every problem of `cycle` against the part and the limits, each naming its key.
pub fn limit_problems(cycle: &CycleSettings, ctx: &CycleContext<'_>) -> Vec<String> {
    let mut p = Vec::new();
    let q_max = ctx.plan.q_w_max_mm3_mm_s;
    for (i, s) in cycle.resolved(ctx.axis.c_speed_rpm).iter().enumerate() {
        let key = stage_key(i, s.kind);
        stage_limits(&mut p, &key, s, ctx, q_max);
    }
    // The air gap is taken coupled, at the first stage's speed.
    let first_rpm = cycle
        .resolved(ctx.axis.c_speed_rpm)
        .first()
        .and_then(|s| s.c_speed_rpm)
        .unwrap_or(ctx.axis.c_speed_rpm);
    let approach = stage_load(ctx.samples, cycle.approach_feed_mm_per_rev, first_rpm);
    if approach.x_velocity_mm_s > ctx.axis.velocity_mm_s {
        p.push(format!(
            "cycle.approach_feed_mm_per_rev = {}: X reaches {:.2} mm/s with the infeed added, axis_limits.velocity_mm_s is {}",
            cycle.approach_feed_mm_per_rev, approach.x_velocity_mm_s, ctx.axis.velocity_mm_s
        ));
    }
    if let Some((lo, hi)) = cycle.x_travel_mm {
        let xs = ctx.samples.samples.iter().map(|s| s.x_mm + ctx.x_offset_mm);
        let (min_x, max_x) = xs.fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x), b.max(x)));
        let top = max_x + (cycle.stock_mm + cycle.approach_mm).max(cycle.lift_off_mm);
        if top > hi {
            p.push(format!(
                "cycle.x_travel_mm = [{lo}, {hi}]: X reaches {top:.4} mm with the stock, approach and lift-off added"
            ));
        }
        if min_x < lo {
            p.push(format!(
                "cycle.x_travel_mm = [{lo}, {hi}]: the finished profile needs X down to {min_x:.4} mm"
            ));
        }
    }
    p
}

fn stage_limits(
    p: &mut Vec<String>,
    key: &str,
    s: &ResolvedStage,
    ctx: &CycleContext<'_>,
    q_max: f64,
) {
    if s.kind == StageKind::Measure {
        return;
    }
    match s.c_speed_rpm {
        Some(rpm) => {
            let load = stage_load(ctx.samples, s.infeed_per_rev_mm, rpm);
            if load.q_w_mm3_mm_s > q_max {
                p.push(format!(
                    "{key}: Q'w {:.3} mm³/(mm·s) at C = {:.1}° ({} mm/rev at {rpm} rpm) exceeds speed_plan.q_w_max_mm3_mm_s = {q_max}",
                    load.q_w_mm3_mm_s, load.q_w_at_c_deg, s.infeed_per_rev_mm
                ));
            }
            if load.x_velocity_mm_s > ctx.axis.velocity_mm_s {
                p.push(format!(
                    "{key}: X reaches {:.2} mm/s with the infeed added at {rpm} rpm, axis_limits.velocity_mm_s is {}",
                    load.x_velocity_mm_s, ctx.axis.velocity_mm_s
                ));
            }
        }
        None => {
            // The plan holds Q′w for `speed_plan.stock_mm` per revolution: a stage on it
            // may take no more (removal grows with the stock taken).
            if s.infeed_per_rev_mm > ctx.plan.stock_mm {
                p.push(format!(
                    "{key}: {} mm/rev on the speed plan, which holds Q'w for speed_plan.stock_mm = {} mm",
                    s.infeed_per_rev_mm, ctx.plan.stock_mm
                ));
            }
            // The plan leaves 0.5 % of the X velocity limit (its speed margin); the infeed
            // at the plan's top C speed must fit in it.
            let infeed_mm_s = s.infeed_per_rev_mm * ctx.axis.c_max_speed_rpm / 60.0;
            if infeed_mm_s > 0.005 * ctx.axis.velocity_mm_s {
                p.push(format!(
                    "{key}: the infeed adds {infeed_mm_s:.3} mm/s to X at the plan's {} rpm, more than the plan's 0.5 % margin of axis_limits.velocity_mm_s",
                    ctx.axis.c_max_speed_rpm
                ));
            }
        }
    }
}
