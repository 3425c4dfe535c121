//! Crash points: in debug builds (so in every test build) or with the `failpoints` feature,
//! `CAMLOOP_CRASH_AT=<step>` or `<step>:<n>` aborts the process the n-th time it reaches a
//! durability step, so a test can prove that a death between any two steps is recovered at
//! the next start. In release builds without the feature a crash point compiles to nothing.
//!
//! Keyed on `debug_assertions` rather than only on the feature: turning the feature on for
//! the tests took a dev-dependency of the package on itself, which made the library's unit
//! tests wait for the library to build first, about 40 s of a clean test build on two cores.
//!
//! Each point sits right after its step has become durable: a crash there lands between that
//! step and the next, which is what `kill -9` at an unlucky moment would do.

/// The environment variable that arms one crash point.
pub const CRASH_AT_VAR: &str = "CAMLOOP_CRASH_AT";

/// Every crash point, in the order a part reaches them (`journaled:…` and `store_commit:…`
/// are one per journal record kind; `resume_written` is reached only by a machine that
/// grinds several features).
pub const STEPS: &[&str] = &[
    // The measurement's record is in the journal, then in the store.
    "journaled:measurement",
    "store_commit:measurement",
    // The table program is rendered (nothing durable yet: the write-ahead record is next).
    "table_rendered",
    // The version's write-ahead record is in the journal.
    "journaled:table_version",
    // The share's manifest holds the version (its text kept in the state folder).
    "manifest:version",
    // The program's temporary on the share is written, then flushed to the device.
    "share_temp_written",
    "share_temp_synced",
    // The manifest says the control may see the version.
    "manifest:delivering",
    // The program files are renamed into place and the share folder flushed.
    "share_renamed",
    // The manifest says the version was read back and verified.
    "manifest:pushed",
    // The part's learning state (with the version's status) is in the journal.
    "journaled:learning_state",
    // The journal's records reached the store, one point per kind.
    "store_commit:table_version",
    "store_commit:table_status",
    "store_commit:learning_state",
    "store_commit:recipe_snapshot",
    // A whole part: the resume point on the share names the next feature.
    "resume_written",
    // A wheel dressing: its record is in the journal, then in the store with its event.
    "journaled:dressing",
    "store_commit:dressing",
    "store_commit:event",
];

/// Aborts the process here when `CAMLOOP_CRASH_AT` names `step` and this is its n-th time.
#[cfg(any(debug_assertions, feature = "failpoints"))]
pub(crate) fn crash_point(step: &'static str) {
    armed::reach(step);
}

/// In a release build without the `failpoints` feature a crash point is nothing.
#[cfg(not(any(debug_assertions, feature = "failpoints")))]
#[inline(always)]
pub(crate) fn crash_point(_step: &'static str) {}

/// The step and count `CAMLOOP_CRASH_AT` names: `<step>` is its first time, `<step>:<n>` its
/// n-th (n ≥ 1). Step names contain `:` themselves, so only a numeric last part is a count.
/// `None` for a step no crash point has, or a count of 0.
#[cfg(any(test, debug_assertions, feature = "failpoints"))]
pub(crate) fn parse_crash_at(text: &str) -> Option<(&'static str, u64)> {
    let (name, nth) = match text.rsplit_once(':') {
        Some((name, n)) if n.bytes().all(|b| b.is_ascii_digit()) && !n.is_empty() => {
            (name, n.parse().ok()?)
        }
        _ => (text, 1),
    };
    let step = STEPS.iter().find(|s| **s == name)?;
    (nth >= 1).then_some((step, nth))
}

#[cfg(any(debug_assertions, feature = "failpoints"))]
mod armed {
    use std::sync::OnceLock;
    use std::sync::atomic::{AtomicU64, Ordering};

    /// The one armed step and how often it has been reached.
    struct Armed {
        step: &'static str,
        nth: u64,
        reached: AtomicU64,
    }

    /// Read once: a crash point is on hot paths, and the environment does not change.
    static ARMED: OnceLock<Option<Armed>> = OnceLock::new();

    fn from_env() -> Option<Armed> {
        let text = std::env::var(super::CRASH_AT_VAR).ok()?;
        match super::parse_crash_at(&text) {
            Some((step, nth)) => Some(Armed {
                step,
                nth,
                reached: AtomicU64::new(0),
            }),
            None => {
                // Said, not ignored: a misspelt step would otherwise look like a step that
                // survives every crash.
                eprintln!(
                    "camloop: {}={text:?} names no crash point (known: {})",
                    super::CRASH_AT_VAR,
                    super::STEPS.join(", ")
                );
                None
            }
        }
    }

    pub(super) fn reach(step: &'static str) {
        let Some(armed) = ARMED.get_or_init(from_env) else {
            return;
        };
        if armed.step != step {
            return;
        }
        let count = armed.reached.fetch_add(1, Ordering::SeqCst) + 1;
        if count == armed.nth {
            eprintln!("camloop: crash point {step} reached (time {count}): aborting");
            // No unwinding, destructors or flushes: as close to `kill -9` as a process can
            // do to itself.
            std::process::abort();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_alone_is_its_first_time_and_a_numeric_tail_is_a_count() {
        assert_eq!(parse_crash_at("share_renamed"), Some(("share_renamed", 1)));
        assert_eq!(
            parse_crash_at("share_renamed:4"),
            Some(("share_renamed", 4))
        );
        assert_eq!(
            parse_crash_at("store_commit:measurement"),
            Some(("store_commit:measurement", 1))
        );
        assert_eq!(
            parse_crash_at("store_commit:measurement:12"),
            Some(("store_commit:measurement", 12))
        );
    }

    #[test]
    fn unknown_steps_and_a_zero_count_arm_nothing() {
        assert_eq!(parse_crash_at("share_renamd"), None);
        assert_eq!(parse_crash_at("share_renamed:0"), None);
        assert_eq!(parse_crash_at("store_commit"), None);
        assert_eq!(parse_crash_at(""), None);
    }

    #[test]
    fn steps_are_named_once() {
        let mut names = STEPS.to_vec();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), STEPS.len());
    }
}
