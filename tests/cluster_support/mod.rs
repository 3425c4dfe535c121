//! A grinding machine outside camloop, as the cluster test needs it: its own thread, its own
//! wheel, its own simulated control. It runs the main program on its share (which calls the
//! table program and couples the table it defines), grinds that table, and drops the gauge's
//! measurement into its inbox as a complete CSV file (written under a temporary name, then
//! renamed). Like a real machine between parts, it waits until the file has been taken
//! (moved to `processed/` or `rejected/`) before it grinds the next part, whichever camloop
//! instance owns it at the time. The machine survives any camloop instance dying.

#![allow(dead_code)]

use super::gauge_drop_support::measurement_csv;
use camloop::core::compensate::Feature;
use camloop::core::measure::RawMeasurement;
use camloop::recipe::Recipe;
use camloop::sim::{CommandedTable, Control, GrinderConfig, PartLabels, SimGrinder, Workpiece};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// One part dropped and what became of it.
#[derive(Debug, Clone)]
pub struct Dropped {
    pub part: String,
    pub file: String,
    /// When the file appeared in the inbox, Unix ms.
    pub dropped_ms: u64,
    /// How long it sat in the inbox before an instance took it.
    pub waited: Duration,
    /// Moved to `rejected/` (with its reason) rather than `processed/`.
    pub rejected: Option<String>,
}

pub struct Machine {
    pub name: String,
    pub share: PathBuf,
    pub inbox: PathBuf,
    /// Shortest time between two parts.
    pub cycle: Duration,
    pub seed: u64,
}

pub fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or(0)
}

/// The demo lobe the cluster test's machines grind.
pub fn demo_feature() -> Feature {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let recipe = Recipe::load(&path).unwrap();
    recipe.feature_setup(&path, "IN1").unwrap().feature
}

impl Machine {
    /// Grinds and drops parts until `stop`; returns every part dropped, in order. A part that
    /// is never taken within `give_up` ends the run (the test then fails on it).
    pub fn run(self, stop: Arc<AtomicBool>, give_up: Duration) -> Vec<Dropped> {
        let feature = demo_feature();
        let Feature::Cam(g) = feature else {
            panic!("the demo lobe is a cam")
        };
        let config = GrinderConfig {
            dress_every_parts: 0,
            ..GrinderConfig::default()
        };
        let mut sim = SimGrinder::new(config, Workpiece::Cam(g), self.seed).unwrap();
        let mut control = Control::new();
        let mut dropped = Vec::new();
        while !stop.load(Ordering::SeqCst) {
            let started = Instant::now();
            let Some(table) = self.coupled_table(&mut control, feature) else {
                // No program on the share yet: no instance has taken this machine.
                std::thread::sleep(Duration::from_millis(100));
                continue;
            };
            let ground = sim.grind(&table).unwrap();
            let part = format!("P{:04}", dropped.len() + 1);
            let labels = PartLabels {
                machine: self.name.clone(),
                part: part.clone(),
                lobe: "IN1".into(),
            };
            let raw = sim.measure(&ground, &labels);
            sim.after_part();
            let file = format!("{}_{part}.csv", self.name);
            let done = self.drop_and_wait(&file, &raw, give_up);
            let Some(done) = done else {
                dropped.push(Dropped {
                    part,
                    file,
                    dropped_ms: now_ms(),
                    waited: give_up,
                    rejected: Some("never taken".into()),
                });
                break;
            };
            dropped.push(Dropped { part, ..done });
            if let Some(rest) = self.cycle.checked_sub(started.elapsed()) {
                std::thread::sleep(rest);
            }
        }
        dropped
    }

    /// The table the control couples when it runs the main program on the share now.
    fn coupled_table(&self, control: &mut Control, feature: Feature) -> Option<CommandedTable> {
        let main = std::fs::read_to_string(self.share.join("CAMLOOP_GRIND.MPF")).ok()?;
        let share = self.share.clone();
        let load =
            move |name: &str| std::fs::read_to_string(share.join(format!("{name}.SPF"))).ok();
        // A program caught mid-replacement is read again at the next cycle, as an operator
        // would restart the cycle after the control's alarm.
        let coupled = control.run(&main, &load).ok()?;
        Some(CommandedTable {
            shape: coupled.shape,
            x_zero_mm: feature.x_zero_mm(),
            wheel_radius_mm: feature.wheel_radius_mm(),
            plan: None,
        })
    }

    fn drop_and_wait(
        &self,
        file: &str,
        raw: &RawMeasurement,
        give_up: Duration,
    ) -> Option<Dropped> {
        let temp = self.inbox.join(format!(".{file}.tmp"));
        std::fs::write(&temp, measurement_csv(raw)).unwrap();
        std::fs::rename(&temp, self.inbox.join(file)).unwrap();
        let dropped_ms = now_ms();
        let at = Instant::now();
        let processed = self.inbox.join("processed").join(file);
        let rejected = self.inbox.join("rejected").join(file);
        while at.elapsed() < give_up {
            let rejected_why =
                std::fs::read_to_string(self.inbox.join(format!("rejected/{file}.reason.txt")))
                    .ok();
            if processed.exists() || rejected.exists() {
                return Some(Dropped {
                    part: String::new(),
                    file: file.to_string(),
                    dropped_ms,
                    waited: at.elapsed(),
                    rejected: rejected.exists().then(|| rejected_why.unwrap_or_default()),
                });
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        None
    }
}
