//! A recipe's own checks, run after parsing: every problem is collected, in the order a
//! reader meets the sections in the file (part, wheel, table, program, learning, speed plan,
//! cycle, lobes, pins), so one run reports them all.

use super::{FollowerKind, Lobe, Pin, Recipe, ShaftKind};
use crate::names::FeatureName;
use std::collections::HashSet;

/// The problems found so far, with the two number rules most fields share.
struct Problems(Vec<String>);

impl Problems {
    fn push(&mut self, problem: String) {
        self.0.push(problem);
    }

    fn positive(&mut self, field: String, v: f64) {
        if !(v.is_finite() && v > 0.0) {
            self.push(format!("{field} = {v}: must be a number > 0"));
        }
    }

    fn finite(&mut self, field: String, v: f64) {
        if !v.is_finite() {
            self.push(format!("{field} = {v}: must be a finite number"));
        }
    }
}

impl Recipe {
    /// Every problem in the recipe, empty when it is sound.
    pub(super) fn problems(&self) -> Vec<String> {
        let mut p = Problems(Vec::new());
        self.check_part(&mut p);
        self.check_table(&mut p);
        self.check_program(&mut p);
        if let Err(e) = self.learning.validate() {
            p.0.extend(e);
        }
        self.check_speed_plan(&mut p);
        if let Some(cycle) = &self.cycle {
            p.0.extend(cycle.problems(self.speed_plan.enabled));
        }
        // Lobe and pin names share one namespace: both name features in the API and store.
        let mut names = HashSet::new();
        for lobe in &self.lobes {
            check_lobe(&mut p, &mut names, lobe);
        }
        for pin in &self.pins {
            check_pin(&mut p, &mut names, pin);
        }
        p.0
    }

    /// The part name, the wheel and whether the features match the shaft's kind.
    fn check_part(&self, p: &mut Problems) {
        // The part name goes into the API's JSON, DFQ K1001/K1002, the programs' comments
        // and the dashboard: one plain rule keeps it safe in all of them.
        if !valid_name(&self.name) {
            p.push(format!(
                "name = `{}`: must be 1–32 letters, digits, '-' or '_'",
                crate::names::quote(&self.name)
            ));
        }
        p.positive("wheel.radius_mm".into(), self.wheel.radius_mm);
        match self.kind {
            ShaftKind::Camshaft if self.lobes.is_empty() => {
                p.push("a camshaft needs at least one [[lobes]]".into())
            }
            ShaftKind::Crankshaft if self.pins.is_empty() => {
                p.push("a crankshaft needs at least one [[pins]]".into())
            }
            ShaftKind::Camshaft if !self.pins.is_empty() => {
                p.push("a camshaft has lobes, not [[pins]]".into())
            }
            ShaftKind::Crankshaft if !self.lobes.is_empty() => {
                p.push("a crankshaft has pins, not [[lobes]]".into())
            }
            _ => {}
        }
    }

    /// The table's point count and whether its number range holds every feature's tables.
    fn check_table(&self, p: &mut Problems) {
        if !crate::core::geometry::POINTS_RANGE.contains(&self.table.points) {
            p.push(format!(
                "table.points = {}: must be 36 to 36000",
                self.table.points
            ));
        }
        let (first, last) = self.table.table_numbers;
        let features = self.features().count() as u32;
        if first == 0 || last < first {
            p.push(format!(
                "table.table_numbers = [{first}, {last}]: must be first ≥ 1 and last ≥ first"
            ));
        } else if last - first + 1 < self.table_numbers_needed() {
            let with_plan = match (self.speed_plan.enabled, self.whole_cycle()) {
                (true, true) => {
                    " (an X pair over C, a C and an X pair over VA each, with the speed plan in the whole cycle)"
                }
                (true, false) => " (an X and a C pair each, with the speed plan on)",
                (false, _) => "",
            };
            p.push(format!(
                "table.table_numbers = [{first}, {last}]: {features} features need {} table numbers{with_plan}, the range holds {}",
                self.table_numbers_needed(),
                last - first + 1
            ));
        }
    }

    /// Each feature's program name, then the program settings.
    fn check_program(&self, p: &mut Problems) {
        for name in self.feature_names() {
            if let Err(e) =
                crate::core::program::validate_program_name(&self.table_program_name(name))
            {
                p.push(format!("program.name with feature {name}: {e}"));
            }
            if self.speed_plan.enabled
                && self.whole_cycle()
                && let Err(e) =
                    crate::core::program::validate_program_name(&self.plan_program_name(name))
            {
                p.push(format!(
                    "program.name with feature {name}, the plan's table program: {e}"
                ));
            }
        }
        if let Err(e) = self.program.validate() {
            p.0.extend(e.0.iter().map(|e| format!("program: {e}")));
        }
    }

    /// The speed plan, when on: its limits against the axes, and C turning forwards.
    fn check_speed_plan(&self, p: &mut Problems) {
        if self.speed_plan.enabled
            && let Err(e) = self.speed_plan.limits(&self.axis_limits).check()
        {
            p.push(format!("speed_plan (with axis_limits): {e}"));
        }
        if self.speed_plan.enabled
            && self.program.c_direction == crate::core::program::CDirection::Reversed
        {
            p.push(
                "speed_plan: enabled with program.c_direction = -1: C's table over the virtual axis is written rising; turn C the other way in the drive, not in the table".into(),
            );
        }
    }
}

/// A feature's name: unique among lobes and pins (the type holds it plain).
fn check_feature_name<'a>(
    p: &mut Problems,
    names: &mut HashSet<&'a FeatureName>,
    at: &str,
    name: &'a FeatureName,
) {
    if !names.insert(name) {
        p.push(format!("{at}: duplicate name"));
    }
}

fn check_lobe<'a>(p: &mut Problems, names: &mut HashSet<&'a FeatureName>, lobe: &'a Lobe) {
    let at = format!("lobes.{}", lobe.name);
    check_feature_name(p, names, &at, &lobe.name);
    p.positive(format!("{at}.base_radius_mm"), lobe.base_radius_mm);
    p.positive(
        format!("{at}.timing_tolerance_deg"),
        lobe.timing_tolerance_deg,
    );
    for (key, v) in [
        ("size_tolerance_um", lobe.size_tolerance_um),
        ("max_error_tolerance_um", lobe.max_error_tolerance_um),
    ] {
        v.inspect(|&v| p.positive(format!("{at}.{key}"), v));
    }
    p.finite(format!("{at}.phase_deg"), lobe.phase_deg);
    p.finite(format!("{at}.z_mm"), lobe.z_mm);
    match (lobe.follower, lobe.roller_radius_mm) {
        (FollowerKind::Roller, None) => {
            p.push(format!("{at}: roller follower needs roller_radius_mm"))
        }
        (FollowerKind::Roller, Some(r)) => p.positive(format!("{at}.roller_radius_mm"), r),
        (_, Some(_)) => p.push(format!(
            "{at}: roller_radius_mm is only for a roller follower"
        )),
        _ => {}
    }
}

fn check_pin<'a>(p: &mut Problems, names: &mut HashSet<&'a FeatureName>, pin: &'a Pin) {
    let at = format!("pins.{}", pin.name);
    check_feature_name(p, names, &at, &pin.name);
    p.positive(format!("{at}.pin_radius_mm"), pin.pin_radius_mm);
    for (field, v) in [
        ("index_tolerance_deg", pin.index_tolerance_deg),
        ("stroke_tolerance_um", pin.stroke_tolerance_um),
        ("roundness_tolerance_um", pin.roundness_tolerance_um),
    ] {
        p.positive(format!("{at}.{field}"), v);
    }
    if let Some(v) = pin.diameter_tolerance_um {
        p.positive(format!("{at}.diameter_tolerance_um"), v);
    }
    p.finite(format!("{at}.phase_deg"), pin.phase_deg);
    p.finite(format!("{at}.z_mm"), pin.z_mm);
    if !(pin.throw_mm.is_finite() && pin.throw_mm >= 0.0) {
        p.push(format!("{at}.throw_mm = {}: must be ≥ 0", pin.throw_mm));
    }
}

/// Names become parts of file names and URLs: keep them plain.
/// The rule of machine names ([`crate::names::check_plain_name`]), for the part name.
fn valid_name(name: &str) -> bool {
    crate::names::check_plain_name(name).is_ok()
}
