//! A wheel dressing: recorded, and the newest table regenerated for the new radius from the
//! same correction (only the learned size is dropped).

use super::super::journal::{EventKind, Pending};
use super::FeatureLoop;
use super::records::event;
use crate::clock::now_ms;
use crate::core::compensate;
use crate::core::learn;
use crate::store::EventLevel;
use tracing::{error, info};

/// What a dressing did, for the API's answer.
#[derive(Debug, Clone, PartialEq)]
pub struct Dressed {
    pub old_radius_mm: f64,
    pub new_radius_mm: f64,
    /// The line the log and the API show.
    pub summary: String,
}

impl FeatureLoop {
    /// A wheel dressing, from the gauge/controller feed, a dropped report or the API. A
    /// radius outside [`compensate::WHEEL_RADIUS_RANGE_MM`] changes nothing. The machine's
    /// `first` feature records the dressing itself; every feature regenerates its table.
    /// `wheel_size_um` is the part of the size correction that was the wheel's (see
    /// [`learn::after_dressing`]).
    pub async fn dress(
        &mut self,
        wheel_radius_mm: f64,
        source: &str,
        first: bool,
        wheel_size_um: f64,
    ) -> anyhow::Result<Dressed> {
        let wheel_radius_mm = compensate::check_wheel_radius(wheel_radius_mm)?;
        let at_ms = now_ms();
        let old = self.memory.wheel_radius_mm;
        info!(machine = %self.name, old_radius_mm = old, new_radius_mm = wheel_radius_mm, source, "wheel dressed: table regenerated for the new radius");
        self.memory.wheel_radius_mm = wheel_radius_mm;
        self.setup.feature = self.setup.feature.with_wheel_radius(wheel_radius_mm);
        learn::after_dressing(&mut self.memory.learning, wheel_size_um);
        if let Some(w) = self.memory.waiting.as_mut() {
            learn::after_dressing(&mut w.learning, wheel_size_um);
        }
        let mut records = Vec::new();
        if first {
            records.push(Pending::Dressing {
                machine: self.name.clone(),
                at_ms,
                old_radius_mm: old,
                new_radius_mm: wheel_radius_mm,
                source: source.to_string(),
            });
            records.push(event(
                &self.name,
                at_ms,
                EventLevel::Info,
                EventKind::WheelDressed,
                format!("wheel radius {old} → {wheel_radius_mm} mm ({source})"),
            ));
        }
        // The newest correction made (delivered or waiting) is regenerated: a dressing is not
        // a learning step.
        let next = self.memory.newest_learning().clone();
        let summary = match compensate::current_table(&next, &self.lobe_loop()) {
            Ok(table) => {
                let reason = format!("wheel dressed to {wheel_radius_mm} mm");
                records.extend(self.deliver(&table, next, &reason, None).await?);
                format!(
                    "wheel radius {old} → {wheel_radius_mm} mm: {}",
                    self.delivery_line()
                )
            }
            Err(e) => {
                error!(machine = %self.name, reason = %e, "no table for the dressed wheel: previous table stays in force");
                self.metrics.update(&self.name, |m| m.alarms_total += 1);
                records.push(event(
                    &self.name,
                    at_ms,
                    EventLevel::Error,
                    EventKind::TableRefused,
                    e.to_string(),
                ));
                format!(
                    "wheel radius {old} → {wheel_radius_mm} mm recorded; table refused, previous kept: {e}"
                )
            }
        };
        records.push(self.learning_record(at_ms));
        self.record(records).await;
        Ok(Dressed {
            old_radius_mm: old,
            new_radius_mm: wheel_radius_mm,
            summary,
        })
    }
}
