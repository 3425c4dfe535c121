//! The grinding cycle of a recipe's `[cycle]`: its stages (rough, semi-finish, measure,
//! finish, spark-out) with their infeed, C speed and wheel speed, the approach and lift-off,
//! and the checks a cycle must pass before any program is written.
//!
//! Pure: settings in, a list of problems (each naming its key) out. The checks that need the
//! part's geometry (removal rate, X velocity with the infeed added) are in [`limits`].

pub mod finish;
pub mod limits;

use serde::Deserialize;

/// What a stage does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StageKind {
    Rough,
    SemiFinish,
    /// The in-process gauge reads the lift with the wheel lifted off and stock still on.
    Measure,
    Finish,
    /// Revolutions without infeed: the wheel head's deflection decays.
    SparkOut,
}

impl StageKind {
    /// The name a recipe gives it.
    pub fn name(self) -> &'static str {
        match self {
            StageKind::Rough => "rough",
            StageKind::SemiFinish => "semi-finish",
            StageKind::Measure => "measure",
            StageKind::Finish => "finish",
            StageKind::SparkOut => "spark-out",
        }
    }

    /// A stage that takes no infeed.
    pub fn without_infeed(self) -> bool {
        matches!(self, StageKind::Measure | StageKind::SparkOut)
    }
}

/// Who writes the grinding cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CycleProgram {
    /// camloop's main program runs the whole cycle (spindle, approach, stages, lift-off).
    #[default]
    Whole,
    /// The machine builder's cycle: camloop writes the tables and today's main program
    /// (couple, turn at size, uncouple); the stages are only checked.
    TableOnly,
}

/// One stage of the cycle.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Stage {
    pub kind: StageKind,
    /// Radial infeed per revolution of C, mm; or give `infeed_mm` (the stage's total).
    #[serde(default)]
    pub infeed_per_rev_mm: Option<f64>,
    /// Radial infeed of the whole stage, mm, spread evenly over its revolutions.
    #[serde(default)]
    pub infeed_mm: Option<f64>,
    /// Revolutions of C in the stage, > 0.
    pub revolutions: f64,
    /// Constant C speed, rpm; leave out for the recipe's `axis_limits.c_speed_rpm`.
    #[serde(default)]
    pub c_speed_rpm: Option<f64>,
    /// Run the stage on the speed plan (finish and spark-out only).
    #[serde(default)]
    pub speed_plan: bool,
    /// Wheel surface speed, m/s; leave out for the cycle's `wheel_speed_m_s`.
    #[serde(default)]
    pub wheel_speed_m_s: Option<f64>,
    /// Dwell after the stage, s.
    #[serde(default)]
    pub dwell_s: f64,
}

/// A recipe's `[cycle]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CycleSettings {
    #[serde(default)]
    pub program: CycleProgram,
    /// Radial stock on the part before the cycle, mm: the stages' infeeds add up to it.
    pub stock_mm: f64,
    /// Air gap above the stock at which the wheel couples, mm; taken at `approach_feed`.
    #[serde(default = "default_approach_mm")]
    pub approach_mm: f64,
    /// Radial feed through the air gap, mm per revolution of C.
    #[serde(default = "default_approach_feed")]
    pub approach_feed_mm_per_rev: f64,
    /// Lift-off from the finished profile after the cycle and for the measurement, mm.
    #[serde(default = "default_lift_off_mm")]
    pub lift_off_mm: f64,
    /// Wheel surface speed of a stage that names none, m/s.
    #[serde(default = "default_wheel_speed")]
    pub wheel_speed_m_s: f64,
    /// Largest wheel surface speed allowed, m/s (the wheel's rating).
    #[serde(default = "default_wheel_max_speed")]
    pub wheel_max_speed_m_s: f64,
    /// The wheel spindle's number (`M1=3 S1=…`).
    #[serde(default = "default_wheel_spindle")]
    pub wheel_spindle: u32,
    /// The PLC's M functions that swing the in-process gauge in and out.
    #[serde(default = "default_gauge_m_codes")]
    pub gauge_m_codes: (u32, u32),
    /// How long the control waits for the same-part finish table after the measurement, s;
    /// then the finish grinds with the table in force.
    #[serde(default = "default_handshake_timeout")]
    pub handshake_timeout_s: f64,
    /// The control's X travel (software limits, MD36100/MD36110), mm; checked when given.
    #[serde(default)]
    pub x_travel_mm: Option<(f64, f64)>,
    /// Gain of the same-part step from the measurement before the finish, 0 < g < 1: the
    /// measurement is of this very part, so it may be taken nearly whole.
    #[serde(default = "default_same_part_gain")]
    pub same_part_gain: f64,
    pub stages: Vec<Stage>,
}

fn default_approach_mm() -> f64 {
    0.1
}
fn default_approach_feed() -> f64 {
    0.05
}
fn default_lift_off_mm() -> f64 {
    2.0
}
fn default_wheel_speed() -> f64 {
    35.0
}
fn default_wheel_max_speed() -> f64 {
    50.0
}
fn default_wheel_spindle() -> u32 {
    1
}
fn default_gauge_m_codes() -> (u32, u32) {
    (62, 63)
}
fn default_handshake_timeout() -> f64 {
    5.0
}
fn default_same_part_gain() -> f64 {
    0.9
}

/// A stage with its infeed resolved: what the program and the simulator run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResolvedStage {
    pub kind: StageKind,
    pub infeed_per_rev_mm: f64,
    pub infeed_mm: f64,
    pub revolutions: f64,
    /// `None`: on the speed plan.
    pub c_speed_rpm: Option<f64>,
    pub wheel_speed_m_s: f64,
    pub dwell_s: f64,
}

/// How close the stages' infeeds must add up to the stock, mm: a tenth of the usual 1 µm
/// resolution of X (MD10200 = 10000 increments per mm), so a sum a reader wrote in µm is
/// never refused for rounding.
pub const STOCK_TOLERANCE_MM: f64 = 1e-4;

/// The key of stage `i` (from 0) in messages: `cycle.stages[2] (finish)`.
pub fn stage_key(i: usize, kind: StageKind) -> String {
    format!("cycle.stages[{i}] ({})", kind.name())
}

impl CycleSettings {
    /// Each stage with its infeed per revolution and total, speeds filled in from
    /// `grinding_c_speed_rpm` and the cycle's wheel speed. Check [`Self::problems`] first:
    /// a stage with both or neither infeed takes 0.
    pub fn resolved(&self, grinding_c_speed_rpm: f64) -> Vec<ResolvedStage> {
        self.stages
            .iter()
            .map(|s| {
                let (per_rev, total) = match (s.infeed_per_rev_mm, s.infeed_mm) {
                    (Some(p), None) => (p, p * s.revolutions),
                    (None, Some(t)) if s.revolutions > 0.0 => (t / s.revolutions, t),
                    _ => (0.0, 0.0),
                };
                ResolvedStage {
                    kind: s.kind,
                    infeed_per_rev_mm: per_rev,
                    infeed_mm: total,
                    revolutions: s.revolutions,
                    c_speed_rpm: (!s.speed_plan)
                        .then(|| s.c_speed_rpm.unwrap_or(grinding_c_speed_rpm)),
                    wheel_speed_m_s: s.wheel_speed_m_s.unwrap_or(self.wheel_speed_m_s),
                    dwell_s: s.dwell_s,
                }
            })
            .collect()
    }

    /// The index of the measure stage, if the cycle has one.
    pub fn measure_stage(&self) -> Option<usize> {
        self.stages
            .iter()
            .position(|s| s.kind == StageKind::Measure)
    }

    /// Every problem of the cycle that needs no geometry, each naming its key; empty when
    /// sound. `speed_plan_on`: whether the recipe's `[speed_plan]` is enabled.
    pub fn problems(&self, speed_plan_on: bool) -> Vec<String> {
        let mut p = Vec::new();
        let positive = |p: &mut Vec<String>, key: &str, v: f64| {
            if !(v.is_finite() && v > 0.0) {
                p.push(format!("{key} = {v}: must be a number > 0"));
            }
        };
        positive(&mut p, "cycle.stock_mm", self.stock_mm);
        positive(&mut p, "cycle.approach_mm", self.approach_mm);
        positive(
            &mut p,
            "cycle.approach_feed_mm_per_rev",
            self.approach_feed_mm_per_rev,
        );
        positive(&mut p, "cycle.lift_off_mm", self.lift_off_mm);
        positive(&mut p, "cycle.wheel_speed_m_s", self.wheel_speed_m_s);
        positive(
            &mut p,
            "cycle.wheel_max_speed_m_s",
            self.wheel_max_speed_m_s,
        );
        positive(
            &mut p,
            "cycle.handshake_timeout_s",
            self.handshake_timeout_s,
        );
        if !(self.same_part_gain > 0.0 && self.same_part_gain < 1.0) {
            p.push(format!(
                "cycle.same_part_gain = {}: must be 0 < g < 1",
                self.same_part_gain
            ));
        }
        if !(1..=99).contains(&self.wheel_spindle) {
            p.push(format!(
                "cycle.wheel_spindle = {}: must be 1 to 99",
                self.wheel_spindle
            ));
        }
        let (m_in, m_out) = self.gauge_m_codes;
        if m_in == m_out || [m_in, m_out].iter().any(|m| !(1..=999).contains(m)) {
            p.push(format!(
                "cycle.gauge_m_codes = [{m_in}, {m_out}]: two different M functions, 1 to 999"
            ));
        }
        if let Some((lo, hi)) = self.x_travel_mm
            && !(lo.is_finite() && hi.is_finite() && lo < hi)
        {
            p.push(format!(
                "cycle.x_travel_mm = [{lo}, {hi}]: must be finite, the first below the second"
            ));
        }
        if self.stages.is_empty() {
            p.push("cycle.stages: a cycle needs at least one stage".into());
        }
        for (i, s) in self.stages.iter().enumerate() {
            self.stage_problems(&mut p, i, s, speed_plan_on);
        }
        self.order_problems(&mut p);
        let total: f64 = self.resolved(1.0).iter().map(|s| s.infeed_mm).sum();
        if self.stock_mm.is_finite() && (total - self.stock_mm).abs() > STOCK_TOLERANCE_MM {
            p.push(format!(
                "cycle.stages: the infeeds add up to {total:.4} mm, cycle.stock_mm is {:.4} mm",
                self.stock_mm
            ));
        }
        p
    }

    fn stage_problems(&self, p: &mut Vec<String>, i: usize, s: &Stage, speed_plan_on: bool) {
        let key = stage_key(i, s.kind);
        if !(s.revolutions.is_finite() && s.revolutions > 0.0) {
            p.push(format!(
                "{key}.revolutions = {}: must be a number > 0",
                s.revolutions
            ));
        }
        match (s.kind.without_infeed(), s.infeed_per_rev_mm, s.infeed_mm) {
            (true, None, None) => {}
            (true, _, _) => p.push(format!("{key}: a {} stage takes no infeed", s.kind.name())),
            (false, Some(_), Some(_)) => p.push(format!(
                "{key}: give infeed_per_rev_mm or infeed_mm, not both"
            )),
            (false, None, None) => p.push(format!("{key}: needs infeed_per_rev_mm or infeed_mm")),
            (false, Some(v), None) | (false, None, Some(v)) => {
                if !(v.is_finite() && v > 0.0) {
                    let field = if s.infeed_mm.is_some() {
                        "infeed_mm"
                    } else {
                        "infeed_per_rev_mm"
                    };
                    p.push(format!("{key}.{field} = {v}: must be a number > 0"));
                }
            }
        }
        if s.kind == StageKind::Measure && s.revolutions < 3.0 {
            p.push(format!(
                "{key}.revolutions = {}: the gauge needs at least 3 revolutions",
                s.revolutions
            ));
        }
        if let Some(v) = s.c_speed_rpm
            && !(v.is_finite() && v > 0.0)
        {
            p.push(format!("{key}.c_speed_rpm = {v}: must be a number > 0"));
        }
        if s.speed_plan {
            if s.c_speed_rpm.is_some() {
                p.push(format!("{key}: give c_speed_rpm or speed_plan, not both"));
            }
            if !matches!(s.kind, StageKind::Finish | StageKind::SparkOut) {
                p.push(format!(
                    "{key}.speed_plan: only finish and spark-out run on the plan"
                ));
            }
            if !speed_plan_on {
                p.push(format!(
                    "{key}.speed_plan: needs [speed_plan] enabled = true"
                ));
            }
        }
        let wheel = s.wheel_speed_m_s.unwrap_or(self.wheel_speed_m_s);
        if !(wheel.is_finite() && wheel > 0.0) {
            p.push(format!(
                "{key}.wheel_speed_m_s = {wheel}: must be a number > 0"
            ));
        } else if wheel > self.wheel_max_speed_m_s {
            p.push(format!(
                "{key}.wheel_speed_m_s = {wheel}: above cycle.wheel_max_speed_m_s = {}",
                self.wheel_max_speed_m_s
            ));
        }
        if !(s.dwell_s.is_finite() && s.dwell_s >= 0.0) {
            p.push(format!("{key}.dwell_s = {}: must be ≥ 0", s.dwell_s));
        }
    }

    /// At most one measure stage, after some infeed and before a finish that follows it.
    fn order_problems(&self, p: &mut Vec<String>) {
        let measures: Vec<usize> = self
            .stages
            .iter()
            .enumerate()
            .filter(|(_, s)| s.kind == StageKind::Measure)
            .map(|(i, _)| i)
            .collect();
        if measures.len() > 1 {
            p.push("cycle.stages: at most one measure stage".into());
        }
        if let Some(&m) = measures.first() {
            let finish_after = self.stages[m..].iter().any(|s| s.kind == StageKind::Finish);
            if !finish_after {
                p.push(format!(
                    "{}: a measurement before the finish needs a finish stage after it",
                    stage_key(m, StageKind::Measure)
                ));
            }
        }
    }
}

#[cfg(test)]
mod tests;
