//! Guards acting part after part: which guard refused or limited a part, its streak of parts
//! in a row, and when that streak becomes one alarm (said once, not per part) or ends. Pure:
//! the shell turns what is returned into events, logs, metrics and the feature's status.

use camloop_core::compensate::{CycleError, GuardError};
use camloop_core::learn::{BoundedQuantity, LearnError};
use serde::{Deserialize, Serialize};

/// Which guard acted on a part: parts in a row with the same kind make a streak. Part of the
/// loop's memory in the journal and the store: the names are its serialized form.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GuardKind {
    /// `max_correction_um`: the lift correction is at or beyond its limit.
    CorrectionLimit,
    /// `max_timing_correction_deg`.
    TimingLimit,
    /// The X velocity, acceleration or jerk of the table (over VA with a speed plan).
    AxisLimits,
    /// The corrected part cannot be ground (geometry) or the table not made.
    Geometry,
    /// The measurement's grid or values do not fit the learning state.
    Measurement,
}

impl GuardKind {
    /// The guard that refused a table.
    pub fn of_refusal(e: &CycleError) -> Self {
        match e {
            CycleError::Learn(
                LearnError::CorrectionTooLarge { .. } | LearnError::AtLimit { .. },
            ) => GuardKind::CorrectionLimit,
            CycleError::Learn(LearnError::TimingTooLarge { .. }) => GuardKind::TimingLimit,
            CycleError::Learn(LearnError::GridMismatch { .. } | LearnError::NonFinite { .. }) => {
                GuardKind::Measurement
            }
            CycleError::Guard(GuardError::Motion { .. } | GuardError::PlanMotion { .. }) => {
                GuardKind::AxisLimits
            }
            CycleError::Guard(_) => GuardKind::Geometry,
        }
    }

    /// The guard that limited a learning step.
    pub fn of_bound(quantity: BoundedQuantity) -> Self {
        match quantity {
            BoundedQuantity::Correction => GuardKind::CorrectionLimit,
            BoundedQuantity::Timing => GuardKind::TimingLimit,
        }
    }

    /// What an operator can do about it.
    pub fn advice(self) -> &'static str {
        match self {
            GuardKind::CorrectionLimit => {
                "check the machine (servo lag, geometry, wheel), dress the wheel, or raise learning.max_correction_um in the recipe"
            }
            GuardKind::TimingLimit => {
                "check the C datum and clamping of the shaft, or raise learning.max_timing_correction_deg"
            }
            GuardKind::AxisLimits => {
                "lower the C speed (axis_limits.c_speed_rpm) or check the X axis limits in the recipe"
            }
            GuardKind::Geometry => "check the wheel radius and the recipe's geometry",
            GuardKind::Measurement => "check the gauge: its grid or values do not fit this feature",
        }
    }
}

/// A guard acting on parts in a row (in the loop's memory, serialized as it stands).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GuardStreak {
    pub kind: GuardKind,
    /// Parts in a row.
    pub parts: u32,
    /// The newest reason, as the guard said it.
    pub reason: String,
    /// The alarm was raised for this streak.
    pub alarmed: bool,
}

/// What a guard acting on a part comes to.
#[derive(Debug, Clone, PartialEq)]
pub struct Acted {
    /// The streak after this part: the memory's new `guard`.
    pub streak: GuardStreak,
    /// The alarm to raise now (an operator must act), its text: once per streak, on the part
    /// that makes it `blocked_alarm_after_parts` long.
    pub alarm: Option<String>,
}

/// Guard `kind` refused or limited part `part` of feature `feature` for `reason`, after the
/// streak `streak` (the memory's): the streak goes on when the same guard acted on the
/// previous part, else starts at one. At `alarm_after_parts` in a row, one alarm with the
/// reason and what the operator can do.
pub fn acted(
    streak: Option<GuardStreak>,
    kind: GuardKind,
    reason: &str,
    part: u64,
    feature: &str,
    alarm_after_parts: u32,
) -> Acted {
    let (parts, alarmed) = match streak {
        Some(s) if s.kind == kind => (s.parts + 1, s.alarmed),
        _ => (1, false),
    };
    let alarm_now = !alarmed && parts >= alarm_after_parts;
    let alarm = alarm_now.then(|| {
        format!(
            "{feature} part {part}: blocked by a guard on {parts} parts in a row: {reason}; {}",
            kind.advice()
        )
    });
    Acted {
        streak: GuardStreak {
            kind,
            parts,
            reason: reason.to_string(),
            alarmed: alarmed || alarm_now,
        },
        alarm,
    }
}

/// Part `part` was learned from with no guard acting: the streak ends (the memory's `guard`
/// becomes None). Returns the text of the event that ends its alarm, when one was raised.
pub fn cleared(streak: Option<GuardStreak>, part: u64, feature: &str) -> Option<String> {
    let streak = streak.filter(|s| s.alarmed)?;
    Some(format!(
        "{feature} part {part}: learned from again; the {:?} guard no longer blocks",
        streak.kind
    ))
}

/// The feature's "blocked by a guard" status for the API and `/metrics`: set while an
/// alarmed streak stands (after a restart too).
pub fn blocked_status(streak: Option<&GuardStreak>) -> Option<String> {
    streak
        .filter(|g| g.alarmed)
        .map(|g| format!("{} parts in a row: {}", g.parts, g.reason))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn streak(kind: GuardKind, parts: u32, alarmed: bool) -> GuardStreak {
        GuardStreak {
            kind,
            parts,
            reason: "old".into(),
            alarmed,
        }
    }

    const ADVICE: &str = "check the machine (servo lag, geometry, wheel), dress the wheel, or raise learning.max_correction_um in the recipe";

    /// Threshold 3: the streak counts same-kind parts, another kind starts over at one, the
    /// alarm comes on the third part only, never again in the same streak.
    #[test]
    fn a_streak_alarms_once_at_the_threshold() {
        use GuardKind::*;
        struct Case {
            before: Option<GuardStreak>,
            kind: GuardKind,
            parts: u32,
            alarmed: bool,
            alarm: bool,
        }
        let cases = [
            Case {
                before: None,
                kind: CorrectionLimit,
                parts: 1,
                alarmed: false,
                alarm: false,
            },
            Case {
                before: Some(streak(CorrectionLimit, 1, false)),
                kind: CorrectionLimit,
                parts: 2,
                alarmed: false,
                alarm: false,
            },
            Case {
                before: Some(streak(CorrectionLimit, 2, false)),
                kind: CorrectionLimit,
                parts: 3,
                alarmed: true,
                alarm: true,
            },
            Case {
                before: Some(streak(CorrectionLimit, 3, true)),
                kind: CorrectionLimit,
                parts: 4,
                alarmed: true,
                alarm: false,
            },
            Case {
                before: Some(streak(TimingLimit, 5, true)),
                kind: CorrectionLimit,
                parts: 1,
                alarmed: false,
                alarm: false,
            },
            Case {
                before: Some(streak(AxisLimits, 2, false)),
                kind: Geometry,
                parts: 1,
                alarmed: false,
                alarm: false,
            },
        ];
        for (i, c) in cases.into_iter().enumerate() {
            let a = acted(c.before, c.kind, "new reason", 17, "IN1", 3);
            assert_eq!(
                a.streak,
                GuardStreak {
                    kind: c.kind,
                    parts: c.parts,
                    reason: "new reason".into(),
                    alarmed: c.alarmed
                },
                "case {i}"
            );
            assert_eq!(a.alarm.is_some(), c.alarm, "case {i}");
        }
    }

    #[test]
    fn the_alarm_names_the_feature_part_count_reason_and_advice() {
        let a = acted(
            Some(streak(GuardKind::CorrectionLimit, 1, false)),
            GuardKind::CorrectionLimit,
            "at the limit",
            9,
            "EX2",
            2,
        );
        assert_eq!(
            a.alarm.as_deref(),
            Some(
                format!(
                    "EX2 part 9: blocked by a guard on 2 parts in a row: at the limit; {ADVICE}"
                )
                .as_str()
            )
        );
        // A threshold of one alarms on the first part.
        assert!(
            acted(None, GuardKind::Geometry, "r", 1, "IN1", 1)
                .alarm
                .is_some()
        );
    }

    #[test]
    fn clearing_speaks_only_for_an_alarmed_streak() {
        assert_eq!(cleared(None, 4, "IN1"), None);
        assert_eq!(
            cleared(Some(streak(GuardKind::TimingLimit, 2, false)), 4, "IN1"),
            None
        );
        assert_eq!(
            cleared(Some(streak(GuardKind::TimingLimit, 5, true)), 4, "IN1").as_deref(),
            Some("IN1 part 4: learned from again; the TimingLimit guard no longer blocks")
        );
    }

    #[test]
    fn the_status_shows_an_alarmed_streak_only() {
        assert_eq!(blocked_status(None), None);
        assert_eq!(
            blocked_status(Some(&streak(GuardKind::Geometry, 2, false))),
            None
        );
        assert_eq!(
            blocked_status(Some(&streak(GuardKind::Geometry, 4, true))).as_deref(),
            Some("4 parts in a row: old")
        );
    }

    /// The streak is part of the loop's memory in journals written before it moved here:
    /// this is that JSON, written by hand from the old record, and it reads and writes back
    /// unchanged.
    #[test]
    fn the_journal_form_is_unchanged() {
        let old = r#"{"kind":"axis_limits","parts":3,"reason":"X jerk","alarmed":true}"#;
        let s: GuardStreak = serde_json::from_str(old).unwrap();
        assert_eq!(
            s,
            GuardStreak {
                kind: GuardKind::AxisLimits,
                parts: 3,
                reason: "X jerk".into(),
                alarmed: true
            }
        );
        assert_eq!(serde_json::to_string(&s).unwrap(), old);
        for (kind, name) in [
            (GuardKind::CorrectionLimit, "\"correction_limit\""),
            (GuardKind::TimingLimit, "\"timing_limit\""),
            (GuardKind::AxisLimits, "\"axis_limits\""),
            (GuardKind::Geometry, "\"geometry\""),
            (GuardKind::Measurement, "\"measurement\""),
        ] {
            assert_eq!(serde_json::to_string(&kind).unwrap(), name);
        }
    }
}
