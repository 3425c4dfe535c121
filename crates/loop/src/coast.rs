//! A part ground but not gauged (the gauge's message was lost or refused, while the control
//! reported which feature it ground), decided: nothing is learned, but the wheel wore all the
//! same, so the table moves on by the drift the loop has learned, as it would have after a
//! measured part. Without this, the feature's next part carries one part of drift more.

use camloop_core::compensate::{self, GuardError, GuardedTable, LobeLoop};
use camloop_core::learn::{LearningState, quantise_correction};

/// Drift below this (µm per part) is none to anticipate: a table would not change by it.
const NO_DRIFT_UM: f64 = 1e-3;

/// What a part ground but not gauged comes to.
#[derive(Debug, Clone)]
pub enum Coast {
    /// Only noted as ground: no drift to anticipate, learning frozen, or a table waits for
    /// the share (the next table is made from the waiting one, not from the one in force).
    Noted,
    /// The drift's table cannot be made: the table in force stays.
    NoTable(GuardError),
    /// Deliver `table`, made from `next` (the correction moved by one part of drift), for
    /// `reason`.
    Table {
        next: Box<LearningState>,
        table: Box<GuardedTable>,
        drift_um: f64,
        reason: String,
    },
}

/// Part `part` was ground with the table of `learning` (in force) and not gauged;
/// `waiting` says a newer table waits for the share.
pub fn coast(learning: &LearningState, waiting: bool, part: &str, lobe: &LobeLoop<'_>) -> Coast {
    let drift_um = learning.size_drift_um_per_part;
    if drift_um.abs() < NO_DRIFT_UM || learning.frozen.is_some() || waiting {
        return Coast::Noted;
    }
    let mut next = learning.clone();
    next.correction_um.iter_mut().for_each(|u| *u -= drift_um);
    quantise_correction(&mut next.correction_um, f64::INFINITY);
    match compensate::current_table(&next, lobe) {
        Ok(table) => Coast::Table {
            next: Box::new(next),
            table: Box::new(table),
            drift_um,
            reason: format!(
                "part {part} ground, not gauged: {drift_um:+.3} µm of drift anticipated"
            ),
        },
        Err(e) => Coast::NoTable(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use camloop_core::compensate::{AxisLimits, Feature, TableRequest};
    use camloop_core::fit::TableForm;
    use camloop_core::geometry::{CamGeometry, Follower};
    use camloop_core::learn::LearningParams;
    use camloop_core::lift::LiftTable;

    /// A round cam: lift 0 everywhere, base radius 20 mm, so any uniform correction is a
    /// valid table and X moves by exactly the correction.
    fn with_lobe<T>(f: impl FnOnce(&LobeLoop<'_>) -> T) -> T {
        let angles: Vec<f64> = (0..360).map(f64::from).collect();
        let nominal = LiftTable::from_points(angles, vec![0.0; 360], "round").unwrap();
        let limits = AxisLimits::default();
        let params = LearningParams::default();
        let lobe = LobeLoop {
            nominal: &nominal,
            feature: Feature::Cam(CamGeometry {
                base_radius_mm: 20.0,
                follower: Follower::Flat,
                wheel_radius_mm: 250.0,
            }),
            request: TableRequest {
                points: 360,
                form: TableForm::G1,
                poly_tolerance_um: 0.1,
            },
            limits: &limits,
            params: &params,
        };
        f(&lobe)
    }

    fn learning(drift_um: f64, frozen: bool) -> LearningState {
        let mut s = LearningState::new(360);
        s.correction_um = vec![-2.0; 360];
        s.size_drift_um_per_part = drift_um;
        s.frozen = frozen.then(|| "reverted".to_string());
        s
    }

    #[test]
    fn nothing_to_anticipate_is_only_noted() {
        with_lobe(|lobe| {
            // Below 1 nm per part, frozen, or a table waiting: noted only.
            for (drift_um, frozen, waiting) in [
                (0.0, false, false),
                (0.000_9, false, false),
                (-0.000_9, false, false),
                (0.5, true, false),
                (0.5, false, true),
            ] {
                assert!(
                    matches!(
                        coast(&learning(drift_um, frozen), waiting, "7", lobe),
                        Coast::Noted
                    ),
                    "drift {drift_um}, frozen {frozen}, waiting {waiting}"
                );
            }
        });
    }

    /// Drift +0.25 µm per part (the part grows): the correction −2 µm moves to −2.25 µm, and
    /// the table's X with it, 0.25 µm lower at every point than the table of −2 µm.
    #[test]
    fn the_table_moves_on_by_one_part_of_drift() {
        with_lobe(|lobe| {
            let before = learning(0.25, false);
            let Coast::Table {
                next,
                table,
                drift_um,
                reason,
            } = coast(&before, false, "7", lobe)
            else {
                panic!("a table was expected");
            };
            assert_eq!(drift_um, 0.25);
            assert_eq!(
                reason,
                "part 7 ground, not gauged: +0.250 µm of drift anticipated"
            );
            assert!(next.correction_um.iter().all(|u| (u + 2.25).abs() < 1e-9));
            let old = compensate::current_table(&before, lobe).unwrap();
            for (a, b) in table.points.iter().zip(&old.points) {
                // A uniform −0.25 µm lift correction on a round cam lowers X by 0.25 µm.
                assert!(
                    (a.x_mm - (b.x_mm - 0.25e-3)).abs() < 1e-9,
                    "{} vs {}",
                    a.x_mm,
                    b.x_mm
                );
            }
        });
    }

    #[test]
    fn a_table_that_cannot_be_made_keeps_the_one_in_force() {
        with_lobe(|lobe| {
            // A wheel radius the geometry refuses: no table.
            let bad = LobeLoop {
                feature: Feature::Cam(CamGeometry {
                    base_radius_mm: 20.0,
                    follower: Follower::Flat,
                    wheel_radius_mm: -1.0,
                }),
                ..*lobe
            };
            assert!(matches!(
                coast(&learning(0.25, false), false, "7", &bad),
                Coast::NoTable(_)
            ));
        });
    }
}
