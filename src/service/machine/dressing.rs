//! A wheel dressing, the shell's half: the loop crate's [`dressing`] checks the report, and
//! the feature's machine moves the correction (by the size step the dresser's infeed tells,
//! or, without a usable infeed, with the wheel's share of the learned size dropped) and
//! delivers the newest table made again for the new radius; here the dressing is recorded
//! and logged.

use super::super::journal::{EventKind, Pending};
use super::records::event;
use super::{FeatureLoop, MachineError};
use crate::clock::now;
use crate::store::EventLevel;
use camloop_loop::Input;
use camloop_loop::dressing::{self, CorrectionMove, Dressing};
use camloop_loop::machine::{self, Finished};
use tracing::{error, info, warn};

/// What a dressing did, for the API's answer.
#[derive(Debug, Clone, PartialEq)]
pub struct Dressed {
    pub old_radius_mm: f64,
    pub new_radius_mm: f64,
    /// The line the log and the API show.
    pub summary: String,
}

/// The wheel after a dressing, as the machine hands it to each feature.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Wheel {
    /// The radius the control now believes, mm.
    pub radius_mm: f64,
    /// The dresser's measured infeed (radius removed), µm, when it reported one.
    pub infeed_um: Option<f64>,
    /// The wheel's share of the size corrections (what all features have in common), µm:
    /// what a dressing without an infeed replaces (see [`dressing::Dressing`]).
    pub share_um: f64,
}

impl FeatureLoop {
    /// A wheel dressing, from the gauge/controller feed, a dropped report or the API. A
    /// radius outside [`crate::core::compensate::WHEEL_RADIUS_RANGE_MM`] changes nothing. The machine's
    /// `first` feature records the dressing itself; every feature regenerates its table.
    pub(super) async fn dress(
        &mut self,
        wheel: &Wheel,
        source: &str,
        first: bool,
    ) -> Result<Dressed, MachineError> {
        let (wheel_radius_mm, infeed_um) =
            dressing::check(wheel.radius_mm, wheel.infeed_um).map_err(MachineError::refused)?;
        let at = now();
        let old = self.machine.memory().wheel_radius_mm;
        info!(machine = %self.name, old_radius_mm = old, new_radius_mm = wheel_radius_mm, infeed_um, source, "wheel dressed: table regenerated for the new radius");
        let dressed = Dressing {
            old_radius_mm: old,
            new_radius_mm: wheel_radius_mm,
            infeed_um,
            share_um: wheel.share_um,
        };
        self.setup.feature = self.setup.feature.with_wheel_radius(wheel_radius_mm);
        let lobe = self.setup.lobe_loop();
        self.machine
            .handle(Input::Dressed(Box::new(machine::Dressed {
                dressing: dressed,
                lobe: &lobe,
                at,
            })));
        let finished = self.run_machine(None).await;
        let mut done = None;
        let mut table = None;
        for f in finished {
            match f {
                Finished::Dressed(d) => done = Some(d),
                Finished::Table(t) => table = Some(t),
                _ => {}
            }
        }
        let done = done.ok_or_else(|| MachineError::Failed {
            reason: "the feature's loop is still working on the previous input".into(),
        })?;
        let how = done.moved.describe();
        self.warn_implausible(&done.moved);
        let mut records = Vec::new();
        if first {
            records.push(Pending::Dressing {
                machine: self.name.clone(),
                at,
                old_radius_mm: old,
                new_radius_mm: wheel_radius_mm,
                infeed_um,
                source: source.to_string(),
            });
            records.push(event(
                &self.name,
                at,
                EventLevel::Info,
                EventKind::WheelDressed,
                dressing::event_text(&dressed, source, &done.moved),
            ));
        }
        let summary = match (done.no_table, table) {
            (None, Some(t)) => {
                records.extend(self.table_records(t)?);
                format!(
                    "wheel radius {old} → {wheel_radius_mm} mm ({how}): {}",
                    self.delivery_line()
                )
            }
            (e, _) => {
                let e = e.unwrap_or_else(|| "no table was made".into());
                error!(machine = %self.name, reason = %e, "no table for the dressed wheel: previous table stays in force");
                self.metrics.update(&self.name, |m| m.alarms_total += 1);
                records.push(event(
                    &self.name,
                    at,
                    EventLevel::Error,
                    EventKind::TableRefused,
                    e.clone(),
                ));
                format!(
                    "wheel radius {old} → {wheel_radius_mm} mm ({how}) recorded; table refused, previous kept: {e}"
                )
            }
        };
        records.push(self.learning_record(at));
        if !self.record(records).await {
            // The dressing's own records were not kept: said so, not answered as done.
            let reason = format!(
                "machine {}: the dressing's records were not kept",
                self.name
            );
            return Err(self.journal_failed(reason));
        }
        Ok(Dressed {
            old_radius_mm: old,
            new_radius_mm: wheel_radius_mm,
            summary,
        })
    }

    /// Warns when the dresser's infeed could not be used ([`dressing::move_correction`]).
    fn warn_implausible(&self, moved: &CorrectionMove) {
        if let CorrectionMove::ShareReplaced {
            implausible_step_um: Some(step),
            limit_um,
        } = moved
        {
            // A radius that moved much more than the infeed is a wheel change or a wrong
            // report: the infeed cannot tell the size step then.
            warn!(machine = %self.name, size_step_um = step, limit_um, "dresser infeed and radius change disagree beyond the correction limit: the wheel's share of the learned size is replaced instead");
        }
    }
}
