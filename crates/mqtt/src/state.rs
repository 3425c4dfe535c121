//! The retained state of each machine's features, and the events' sequence numbers.
//!
//! `<prefix>/<machine>/<feature>/state` holds what is true now, not the newest event: the
//! alarms in force (a guard blocking, the share or the disk away, a table refused), the
//! table version in force, whether learning is frozen, and the last part's verdict. A part
//! that passes does not clear an alarm; only the event that ends it does (`guard_cleared`,
//! `share_back`, `disk_space_back`, `learning_resumed`, a delivered table).
//!
//! Every event gets the next sequence number (`seq`), so a consumer drops the one duplicate
//! that at-least-once delivery allows. Both survive a restart in `state.json` next to the
//! queue.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use camloop_core::levels::Verdict;
use camloop_core::names::{FeatureName, MachineName};
use camloop_loop::{MACHINE_LEVEL, PartId, PlantEvent};

/// State file name in the queue folder.
pub(crate) const STATE_FILE: &str = "state.json";

/// One feature's current state, as retained on its state topic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct FeatureState {
    pub machine: MachineName,
    pub feature: FeatureName,
    /// Any alarm in force (machine-wide ones included).
    pub alarm: bool,
    /// The alarms in force, by kind (`blocked_by_guard`, `table_refused`, …).
    pub alarms: BTreeSet<String>,
    /// The table version on the control (last delivered).
    pub version_in_force: Option<u64>,
    pub frozen: bool,
    pub last_part: Option<PartId>,
    pub last_verdict: Option<Verdict>,
    /// The sequence number of the event that last changed this state.
    pub seq: u64,
    /// When that event happened (`at_ms` on the wire and in `state.json`, Unix ms).
    #[serde(rename = "at_ms", with = "camloop_loop::unix_ms")]
    pub at: jiff::Timestamp,
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct Machine {
    alarms: BTreeSet<String>,
    frozen: bool,
    /// Per feature: its own alarms and facts (machine-wide ones are merged when shown).
    features: BTreeMap<FeatureName, FeatureState>,
}

/// The states of every machine seen, and the next sequence number.
#[derive(Debug, Default, Serialize, Deserialize)]
pub(crate) struct Tracker {
    next_seq: u64,
    machines: BTreeMap<MachineName, Machine>,
    #[serde(skip)]
    path: PathBuf,
}

/// Alarms an event raises (`Some(kind)`) or the kinds it clears.
fn alarm_change(kind: &str) -> (Option<&str>, &'static [&'static str]) {
    match kind {
        "blocked_by_guard"
        | "share_unavailable"
        | "disk_full"
        | "journal_quarantined"
        | "learning_held" => (Some(kind), &[]),
        "guard_cleared" => (None, &["blocked_by_guard"]),
        "share_back" => (None, &["share_unavailable"]),
        "disk_space_back" => (None, &["disk_full"]),
        "learning_resumed" => (None, &["learning_held"]),
        _ => (None, &[]),
    }
}

impl Tracker {
    /// The tracker saved in `dir` (a missing or unreadable file starts afresh: the states
    /// then rebuild from the next events).
    pub fn open(dir: &Path) -> Self {
        let path = dir.join(STATE_FILE);
        let mut t: Tracker = std::fs::read_to_string(&path)
            .ok()
            .and_then(|text| serde_json::from_str(&text).ok())
            .unwrap_or_default();
        t.path = path;
        t
    }

    /// Takes `event`: its sequence number, and the state topics and payloads it changed.
    pub fn apply(&mut self, event: &PlantEvent, prefix: &str) -> (u64, Vec<(String, String)>) {
        self.next_seq += 1;
        let seq = self.next_seq;
        let m = self.machines.entry(event.machine().clone()).or_default();
        let feature = event.feature();
        match event {
            PlantEvent::LearningFrozen { .. } => m.frozen = true,
            PlantEvent::Alarm { kind, .. } => {
                let (raise, clear) = alarm_change(kind);
                m.alarms.extend(raise.map(str::to_owned));
                m.alarms.retain(|a| !clear.contains(&a.as_str()));
                if kind == "learning_resumed" {
                    m.frozen = false;
                }
            }
            _ => {}
        }
        let touched: Vec<FeatureName> = if feature == MACHINE_LEVEL {
            let mut all: Vec<FeatureName> = m.features.keys().cloned().collect();
            if all.is_empty() {
                all.push(FeatureName::new(MACHINE_LEVEL).expect("`machine` follows the name rule"));
            }
            all
        } else {
            event.feature_name().into_iter().cloned().collect()
        };
        let mut out = Vec::new();
        for f in touched {
            let s = m.features.entry(f.clone()).or_insert_with(|| FeatureState {
                machine: event.machine().clone(),
                feature: f.clone(),
                alarm: false,
                alarms: BTreeSet::new(),
                version_in_force: None,
                frozen: false,
                last_part: None,
                last_verdict: None,
                seq: 0,
                at: jiff::Timestamp::UNIX_EPOCH,
            });
            s.machine = event.machine().clone();
            feature_facts(s, event);
            s.seq = seq;
            s.at = event.at();
            let mut shown = s.clone();
            shown.alarms.extend(m.alarms.iter().cloned());
            shown.alarm = !shown.alarms.is_empty();
            shown.frozen = m.frozen;
            let topic = format!("{prefix}/{}/{f}/state", event.machine());
            // Strings, numbers, booleans: serializing cannot fail.
            let payload = serde_json::to_string(&shown).expect("a state serializes to JSON");
            out.push((topic, payload));
        }
        (seq, out)
    }

    /// Saves the tracker (temporary file, then rename).
    pub(crate) fn save(&self) -> std::io::Result<()> {
        let tmp = self.path.with_extension("json.tmp");
        let text = serde_json::to_string(self).map_err(std::io::Error::other)?;
        std::fs::write(&tmp, text)?;
        std::fs::rename(&tmp, &self.path)
    }
}

/// What a feature's own event says about it.
fn feature_facts(s: &mut FeatureState, event: &PlantEvent) {
    match event {
        PlantEvent::PartAnalysed {
            part,
            verdict,
            ground_with_version,
            ..
        } => {
            s.last_part = Some(part.clone());
            s.last_verdict = Some(*verdict);
            if s.version_in_force.is_none()
                && let Some(v) = ground_with_version
            {
                s.version_in_force = Some(v.get());
            }
        }
        PlantEvent::TableDelivered { version, .. } => {
            s.version_in_force = Some(version.get());
            s.alarms.remove("table_refused");
        }
        PlantEvent::TableRefused { .. } => {
            s.alarms.insert("table_refused".into());
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use camloop_core::levels::EventLevel;

    fn part(n: u32, verdict: Verdict) -> PlantEvent {
        PlantEvent::PartAnalysed {
            machine: "M1".parse().unwrap(),
            feature: "IN1".parse().unwrap(),
            part: format!("P{n}").parse().unwrap(),
            at: jiff::Timestamp::from_millisecond(i64::from(n)).unwrap(),
            verdict,
            max_profile_error_um: 1.0,
            base_radius_error_um: 0.0,
            phase_error_deg: 0.0,
            ground_with_version: camloop_loop::TableVersion::new(3),
            repeatability_um: None,
        }
    }

    fn alarm(kind: &str) -> PlantEvent {
        PlantEvent::Alarm {
            machine: "M1".parse().unwrap(),
            at: jiff::Timestamp::from_millisecond(9).unwrap(),
            level: EventLevel::Warn,
            kind: kind.into(),
            message: "m".into(),
        }
    }

    fn state(t: &mut Tracker, e: &PlantEvent) -> (u64, serde_json::Value) {
        let (seq, states) = t.apply(e, "p");
        assert_eq!(states[0].0, "p/M1/IN1/state");
        (seq, serde_json::from_str(&states[0].1).unwrap())
    }

    #[test]
    fn an_alarm_holds_until_the_event_that_ends_it_and_a_part_does_not_overwrite_it() {
        let dir = tempfile::tempdir().unwrap();
        let mut t = Tracker::open(dir.path());
        let (seq, s) = state(&mut t, &part(1, Verdict::Pass));
        assert_eq!(
            (seq, s["alarm"].clone(), s["version_in_force"].clone()),
            (1, false.into(), 3.into())
        );
        let (_, s) = state(&mut t, &alarm("blocked_by_guard"));
        assert_eq!(s["alarm"], true);
        let (_, s) = state(&mut t, &part(2, Verdict::Fail));
        assert_eq!(
            (s["alarm"].clone(), s["last_verdict"].clone()),
            (true.into(), "fail".into())
        );
        assert_eq!(s["alarms"], serde_json::json!(["blocked_by_guard"]));
        let frozen = PlantEvent::LearningFrozen {
            machine: "M1".parse().unwrap(),
            at: jiff::Timestamp::from_millisecond(10).unwrap(),
            reason: "diverging".into(),
        };
        assert_eq!(state(&mut t, &frozen).1["frozen"], true);
        let delivered = PlantEvent::TableDelivered {
            machine: "M1".parse().unwrap(),
            feature: "IN1".parse().unwrap(),
            version: camloop_loop::TableVersion::new(7).unwrap(),
            at: jiff::Timestamp::from_millisecond(11).unwrap(),
        };
        let (_, s) = state(&mut t, &delivered);
        // The retained payload keeps its key (`at_ms`, Unix ms) whatever the field's name.
        assert_eq!(s["at_ms"], 11);
        assert_eq!(
            (s["version_in_force"].clone(), s["frozen"].clone()),
            (7.into(), true.into())
        );
        let (seq, s) = state(&mut t, &alarm("guard_cleared"));
        assert_eq!(
            (s["alarm"].clone(), s["last_part"].clone()),
            (false.into(), "P2".into())
        );
        assert_eq!(seq, 6);
        // The sequence and the states survive a restart.
        t.save().unwrap();
        let mut again = Tracker::open(dir.path());
        let (seq, s) = state(&mut again, &part(3, Verdict::Pass));
        assert_eq!(
            (seq, s["version_in_force"].clone(), s["frozen"].clone()),
            (7, 7.into(), true.into())
        );
    }
}
