//! The C speed plan in the service (`[speed_plan] enabled = true`): each table is delivered
//! as the two-table program over the virtual axis VA (C = f(VA), X = g(VA)) with the same
//! provenance and numbering as a constant-speed table, after the corrected X table has been
//! checked against the X limits over VA (a violation is a guard refusal, never a delivery).
//!
//! The plan is made for the nominal part on the wheel the control believes, and made again
//! only when that radius changes (a dressing): between dressings it is fixed, so the servo
//! lag it leaves is a repeatable shape the loop learns like any other. When it is made
//! again, the lift-domain correction and the learned timing in C are carried over (both
//! live in the part frame, not in time); the part of the timing that the lag contributes
//! changes with VA's speed by well under its deadband for a dressing, and is re-learned by
//! the next steps as usual.

use super::FeatureLoop;
use crate::core::compensate::{GuardError, GuardedTable};
use crate::core::learn::LearningState;
use crate::core::program::{ProgramSettings, fmt_fixed};
use crate::core::speed_plan::render::{VaProgramSettings, render_va_table_program};
use crate::core::speed_plan::tables::VaTables;
use crate::core::speed_plan::{self, TimeLaw};
use crate::core::turn::{self, TurnSetup};
use crate::recipe::{FeatureSetup, plan_program_name};
use tracing::error;

/// The virtual leading axis' name in the programs.
const VIRTUAL_AXIS: &str = "VA";

/// What a feature's loop keeps of its plan.
#[derive(Debug, Default)]
pub(crate) struct PlanState {
    /// The plan's time law and the wheel radius (bits) it was made for.
    law: Option<(u64, TimeLaw)>,
    /// The tables last made, by what they were made from (correction digest, timing,
    /// radius), so the guard's check and the delivery make them once.
    last: Option<(String, Result<VaTables, GuardError>)>,
    /// VA's speed of the table being delivered, rev/min (committed to the main program once
    /// the share confirms it).
    pub(super) pending_va_rpm: Option<f64>,
}

/// The turn's setup: `setup`'s, with the plan's time law for the wheel believed now when the
/// recipe grinds with a plan (see [`FeatureLoop::refresh_plan`]).
pub(super) fn turn_setup<'a>(setup: &'a FeatureSetup, plan: &'a PlanState) -> TurnSetup<'a> {
    let radius_bits = setup.feature.wheel_radius_mm().to_bits();
    let law = match &plan.law {
        Some((bits, law)) if setup.speed_plan.enabled && *bits == radius_bits => Some(law),
        _ => None,
    };
    TurnSetup {
        plan: law,
        ..setup.turn_setup()
    }
}

/// The table settings of `setup` for the two-table program, with these numbers.
pub(super) fn va_settings(setup: &FeatureSetup, x_table: u32, c_table: u32) -> VaProgramSettings {
    let p = &setup.program;
    VaProgramSettings {
        name: p.name.clone(),
        virtual_axis: VIRTUAL_AXIS.to_string(),
        x_axis: p.following_axis.clone(),
        c_axis: p.leading_axis.clone(),
        x_decimals: usize::from(p.x_decimals),
        c_decimals: usize::from(p.c_decimals),
        x_table,
        c_table,
        c_offset_deg: p.c_offset_deg,
        x_offset_mm: p.x_offset_mm,
        comment_lines: p.comment_lines.clone(),
        provenance: None,
    }
}

impl FeatureLoop {
    /// The plan's time law for the wheel believed now, made again when the radius changed.
    fn plan_law(&mut self) -> anyhow::Result<TimeLaw> {
        let radius_bits = self.setup.feature.wheel_radius_mm().to_bits();
        if let Some((bits, law)) = &self.plan.law
            && *bits == radius_bits
        {
            return Ok(law.clone());
        }
        let law = law_for(&self.setup, self.setup.feature.wheel_radius_mm())?;
        self.plan.law = Some((radius_bits, law.clone()));
        Ok(law)
    }

    /// Makes the plan for the wheel believed now, before a turn, so the turn guards its
    /// table over VA ([`turn_setup`]). A plan that cannot be made at all (its
    /// geometry) is said here; the turn then decides without it and the delivery says so
    /// and keeps the table in force.
    pub(super) fn refresh_plan(&mut self) {
        if !self.setup.speed_plan.enabled {
            return;
        }
        if let Err(e) = self.plan_law() {
            error!(machine = %self.name, lobe = %self.setup.name, error = format!("{e:#}"), "speed plan cannot be made");
        }
    }

    /// Keeps the tables over VA the turn made (and guarded) for its new `table` (made from
    /// `next`), so the delivery renders them without making them again.
    pub(super) fn keep_planned(
        &mut self,
        table: &GuardedTable,
        next: &LearningState,
        tables: VaTables,
    ) {
        let key = self.plan_key(table, next);
        self.plan.last = Some((key, Ok(tables)));
    }

    /// What the tables over VA are made from: correction, timing and wheel radius.
    fn plan_key(&self, table: &GuardedTable, next: &LearningState) -> String {
        format!(
            "{} {} {}",
            crate::core::turn::correction_sha256(&next.correction_um),
            table.timing_offset_deg.to_bits(),
            self.setup.feature.wheel_radius_mm().to_bits()
        )
    }

    /// The tables over VA of `table` (made from `next`), checked against the X limits; None
    /// when the recipe grinds at constant speed.
    fn planned(
        &mut self,
        table: &GuardedTable,
        next: &LearningState,
    ) -> anyhow::Result<Option<Result<VaTables, GuardError>>> {
        if !self.setup.speed_plan.enabled {
            return Ok(None);
        }
        let law = self.plan_law()?;
        let key = self.plan_key(table, next);
        if let Some((k, tables)) = &self.plan.last
            && *k == key
        {
            return Ok(Some(tables.clone()));
        }
        let tables = turn::planned_tables(&self.setup.lobe_loop(), &law, next, table);
        self.plan.last = Some((key, tables.clone()));
        Ok(Some(tables))
    }

    /// The table program of `table` for `settings` (number, provenance, comments): the
    /// constant-speed program, or with the plan the two-table program, C's number
    /// alternating in step with X's. Sets the VA speed the main program must carry.
    pub(super) fn render_table(
        &mut self,
        table: &GuardedTable,
        next: &LearningState,
        settings: &ProgramSettings,
    ) -> anyhow::Result<String> {
        let Some(tables) = self.planned(table, next)? else {
            self.plan.pending_va_rpm = None;
            return Ok(table.render(settings)?);
        };
        let tables = tables
            .map_err(|e| anyhow::anyhow!("{}: table not delivered: {e}", self.setup.label))?;
        let (x_pair, c_pair) = (self.setup.table_pair, self.setup.c_table_pair);
        let c_pair = c_pair.ok_or_else(|| anyhow::anyhow!("the recipe gave C no table numbers"))?;
        // Every pair alternates in step with X's, the number the share checks: the tables a
        // version defines are never the ones the version before it defined.
        let in_step = |pair: (u32, u32)| {
            if settings.table_number == x_pair.0 {
                pair.0
            } else {
                pair.1
            }
        };
        self.plan.pending_va_rpm = Some(tables.va_speed_rpm);
        let Some(plan_x_pair) = self.setup.plan_x_table_pair else {
            let mut va = va_settings(&self.setup, settings.table_number, in_step(c_pair));
            va.comment_lines = settings.comment_lines.clone();
            va.provenance = settings.provenance.clone();
            return Ok(render_va_table_program(&tables, &va)?);
        };
        // The whole cycle grinds some stages at constant C speed (X over C, this number) and
        // some on the plan (C and X over VA, their own pairs): one version is both programs,
        // one text, pushed together (see `core::program::split_program_files`).
        let constant = table.render(settings)?;
        let mut va = va_settings(&self.setup, in_step(plan_x_pair), in_step(c_pair));
        va.name = plan_program_name(&self.setup.program.name);
        va.comment_lines = settings.comment_lines.clone();
        va.provenance = settings.provenance.clone();
        Ok(constant + &render_va_table_program(&tables, &va)?)
    }

    /// The VA speed (rev/min) of a table program made for a wheel of `wheel_radius_mm` and
    /// just delivered, None at constant speed. Every table is rendered with the plan for
    /// the wheel it was made for, so that plan's speed is the program's: known here, never
    /// read back from the share.
    pub(super) fn va_speed_delivered(&self, wheel_radius_mm: f64) -> Option<f64> {
        if !self.setup.speed_plan.enabled {
            return None;
        }
        match &self.plan.law {
            Some((bits, law)) if *bits == wheel_radius_mm.to_bits() => Some(60.0 / law.period_s()),
            // A waiting table made for a wheel dressed since: its own plan.
            _ => law_for(&self.setup, wheel_radius_mm)
                .ok()
                .map(|law| 60.0 / law.period_s()),
        }
    }

    /// The plan made at start for the wheel believed. The memory says the VA speed the
    /// table in force was rendered for (the feature's machine keeps it with the version, so
    /// the share's program is never read back); when that is this plan's, the main program
    /// takes it as on the share. Returns true when the table in force is not this plan's
    /// (new limits, a plan newly switched on, a memory from before): it must be delivered
    /// again.
    pub(super) fn plan_at_start(&mut self) -> anyhow::Result<bool> {
        if !self.setup.speed_plan.enabled {
            return Ok(false);
        }
        let law = self.plan_law()?;
        let va_speed_rpm = 60.0 / law.period_s();
        self.plan.pending_va_rpm = Some(va_speed_rpm);
        let in_force = self.machine.memory().in_force_va_speed_rpm;
        // As the programs write it: a plan made again for the same wheel is the same plan.
        let same = in_force.map(|r| fmt_fixed(r, 4)) == Some(fmt_fixed(va_speed_rpm, 4));
        if same && self.machine.memory().waiting.is_none() {
            self.main.delivered(&self.setup.name, va_speed_rpm)?;
        }
        Ok(!same)
    }
}

/// The plan's time law for `setup`'s nominal part on a wheel of `wheel_radius_mm`.
fn law_for(setup: &FeatureSetup, wheel_radius_mm: f64) -> anyhow::Result<TimeLaw> {
    let feature = setup.feature.with_wheel_radius(wheel_radius_mm);
    let part = feature.part(&setup.nominal)?;
    let limits = setup.speed_plan.limits(&setup.limits);
    Ok(speed_plan::plan(&part, &limits)?.law)
}
