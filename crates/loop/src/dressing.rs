//! A wheel dressing, decided: the reported radius and infeed checked, and the learned
//! correction (in force and waiting) moved by the size step the dresser's infeed tells when
//! that step is plausible, or else by replacing the wheel's share of the learned size. The
//! service and the simulated cell run this one policy; the shell records and logs what it
//! returns and regenerates the table.

use camloop_core::compensate::{WheelRadiusError, check_wheel_radius};
use camloop_core::learn::{self, DresserInfeedError, LearningState};

/// A dressing as reported, with what the loop knows of the wheel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dressing {
    /// The radius the control believed before, mm.
    pub old_radius_mm: f64,
    /// The radius the control believes now, mm.
    pub new_radius_mm: f64,
    /// The dresser's measured infeed (radius removed), µm, when it reported one.
    pub infeed_um: Option<f64>,
    /// The wheel's share of the size corrections (what all features have in common), µm:
    /// what a dressing without a usable infeed replaces (see [`learn::after_dressing`]).
    pub share_um: f64,
}

/// A dressing report the loop refuses: nothing changes.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum DressingError {
    #[error(transparent)]
    Radius(#[from] WheelRadiusError),
    #[error(transparent)]
    Infeed(#[from] DresserInfeedError),
}

/// Checks a reported radius (mm) and infeed (µm): returns them when both are plausible.
pub fn check(radius_mm: f64, infeed_um: Option<f64>) -> Result<(f64, Option<f64>), DressingError> {
    let radius_mm = check_wheel_radius(radius_mm)?;
    let infeed_um = infeed_um.map(learn::check_dresser_infeed).transpose()?;
    Ok((radius_mm, infeed_um))
}

/// How the correction was moved.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CorrectionMove {
    /// By the size step the dresser's infeed tells.
    SizeStep { infeed_um: f64, step_um: f64 },
    /// The wheel's share of the learned size replaced: no infeed, or one whose size step
    /// (`implausible_step_um`) exceeds `limit_um` (a wheel change or a wrong report, which
    /// the shell warns about).
    ShareReplaced {
        implausible_step_um: Option<f64>,
        limit_um: f64,
    },
}

impl CorrectionMove {
    /// How, in the words of the dressing's event and the API's answer.
    pub fn describe(&self) -> String {
        match self {
            CorrectionMove::SizeStep { infeed_um, step_um } => {
                format!("dresser infeed {infeed_um:.2} µm: size step {step_um:+.2} µm")
            }
            CorrectionMove::ShareReplaced { .. } => {
                "no usable infeed: the wheel's share of the learned size replaced".to_string()
            }
        }
    }
}

/// Moves every state of `states` (the learning in force and the waiting table's) for
/// `dressing`: by the size step when the dresser measured its infeed and the step is within
/// `max_correction_um` (a radius that moved much more than the infeed is a wheel change or
/// a wrong report: the infeed cannot tell the size step then), else by replacing the
/// wheel's share.
pub fn move_correction<'a>(
    states: impl IntoIterator<Item = &'a mut LearningState>,
    dressing: &Dressing,
    max_correction_um: f64,
) -> CorrectionMove {
    let step_um = dressing.infeed_um.map(|infeed_um| {
        let step =
            learn::dressing_size_step_um(dressing.old_radius_mm, dressing.new_radius_mm, infeed_um);
        (infeed_um, step)
    });
    match step_um {
        Some((infeed_um, step_um)) if step_um.abs() <= max_correction_um => {
            states
                .into_iter()
                .for_each(|s| learn::after_measured_dressing(s, step_um));
            CorrectionMove::SizeStep { infeed_um, step_um }
        }
        _ => {
            states
                .into_iter()
                .for_each(|s| learn::after_dressing(s, dressing.share_um));
            CorrectionMove::ShareReplaced {
                implausible_step_um: step_um.map(|(_, step)| step),
                limit_um: max_correction_um,
            }
        }
    }
}

/// The text of the dressing's event: radii, who reported it and how the correction moved.
pub fn event_text(dressing: &Dressing, source: &str, how: &CorrectionMove) -> String {
    format!(
        "wheel radius {} → {} mm ({source}); {}",
        dressing.old_radius_mm,
        dressing.new_radius_mm,
        how.describe()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A state with a uniform correction of `size_um` and a dressing offset of `offset_um`.
    fn state(size_um: f64, offset_um: f64) -> LearningState {
        let mut s = LearningState::new(4);
        s.correction_um = vec![size_um; 4];
        s.dressing_offset_um = offset_um;
        s
    }

    /// Radius 250 → 249.99 mm is −10 µm believed; with an infeed the size step is
    /// −10 µm + infeed, and the correction moves by minus that step. Without a usable
    /// infeed the correction becomes size − share + offset. Limit 50 µm.
    #[test]
    fn the_correction_moves_by_the_step_or_by_the_share() {
        struct Case {
            infeed_um: Option<f64>,
            expect_um: f64,
            expect: CorrectionMove,
        }
        let limit_um = 50.0;
        let cases = [
            // Infeed 12 µm: step +2 µm, the correction −4 → −6 µm.
            Case {
                infeed_um: Some(12.0),
                expect_um: -6.0,
                expect: CorrectionMove::SizeStep {
                    infeed_um: 12.0,
                    step_um: 2.0,
                },
            },
            // Infeed 59.9 µm, step +49.9 µm: just within the limit, a step, −4 → −53.9 µm.
            // (At exactly 50 µm the binary 249.99 − 250 puts the step a hair over.)
            Case {
                infeed_um: Some(59.9),
                expect_um: -53.9,
                expect: CorrectionMove::SizeStep {
                    infeed_um: 59.9,
                    step_um: 49.9,
                },
            },
            // Infeed 70 µm, step +60 µm beyond the limit: share −3 replaced by offset 1.5,
            // −4 − (−3) + 1.5 = 0.5 µm.
            Case {
                infeed_um: Some(70.0),
                expect_um: 0.5,
                expect: CorrectionMove::ShareReplaced {
                    implausible_step_um: Some(60.0),
                    limit_um,
                },
            },
            // No infeed: the share is replaced as above.
            Case {
                infeed_um: None,
                expect_um: 0.5,
                expect: CorrectionMove::ShareReplaced {
                    implausible_step_um: None,
                    limit_um,
                },
            },
        ];
        for (i, c) in cases.into_iter().enumerate() {
            let dressing = Dressing {
                old_radius_mm: 250.0,
                new_radius_mm: 249.99,
                infeed_um: c.infeed_um,
                share_um: -3.0,
            };
            let (mut in_force, mut waiting) = (state(-4.0, 1.5), state(-4.0, 1.5));
            let how = move_correction([&mut in_force, &mut waiting], &dressing, limit_um);
            match (how, c.expect) {
                (
                    CorrectionMove::SizeStep { infeed_um, step_um },
                    CorrectionMove::SizeStep {
                        infeed_um: i_um,
                        step_um: s_um,
                    },
                ) => {
                    assert_eq!(infeed_um, i_um, "case {i}");
                    // 249.99 − 250 is not exact in binary: the step is within 1e-9 µm.
                    assert!((step_um - s_um).abs() < 1e-9, "case {i}: step {step_um}");
                }
                (
                    CorrectionMove::ShareReplaced {
                        implausible_step_um: got,
                        limit_um: l,
                    },
                    CorrectionMove::ShareReplaced {
                        implausible_step_um: want,
                        limit_um: lw,
                    },
                ) => {
                    assert_eq!(l, lw, "case {i}");
                    assert_eq!(got.is_some(), want.is_some(), "case {i}");
                    if let (Some(g), Some(w)) = (got, want) {
                        assert!((g - w).abs() < 1e-9, "case {i}");
                    }
                }
                (got, want) => panic!("case {i}: {got:?}, expected {want:?}"),
            }
            // Kept to whole nanometres: the expected value to 1 nm.
            for s in [&in_force, &waiting] {
                for u in &s.correction_um {
                    assert!((u - c.expect_um).abs() < 1e-6, "case {i}: {u} µm");
                }
            }
            let measured = matches!(c.expect, CorrectionMove::SizeStep { .. });
            assert_eq!(in_force.dressing_measured, measured, "case {i}");
            assert_eq!(in_force.dressed, !measured, "case {i}");
        }
    }

    #[test]
    fn the_report_is_checked_before_anything_moves() {
        assert_eq!(check(249.5, Some(20.0)), Ok((249.5, Some(20.0))));
        assert_eq!(check(249.5, None), Ok((249.5, None)));
        assert!(matches!(check(-1.0, None), Err(DressingError::Radius(_))));
        assert!(matches!(
            check(249.5, Some(-5.0)),
            Err(DressingError::Infeed(_))
        ));
        assert!(matches!(
            check(249.5, Some(5000.0)),
            Err(DressingError::Infeed(_))
        ));
    }

    #[test]
    fn the_event_says_radii_source_and_how() {
        let d = Dressing {
            old_radius_mm: 250.0,
            new_radius_mm: 249.98,
            infeed_um: Some(21.5),
            share_um: 0.0,
        };
        let how = CorrectionMove::SizeStep {
            infeed_um: 21.5,
            step_um: 1.5,
        };
        assert_eq!(
            event_text(&d, "api", &how),
            "wheel radius 250 → 249.98 mm (api); dresser infeed 21.50 µm: size step +1.50 µm"
        );
        let how = CorrectionMove::ShareReplaced {
            implausible_step_um: None,
            limit_um: 50.0,
        };
        assert_eq!(
            event_text(&d, "plc", &how),
            "wheel radius 250 → 249.98 mm (plc); no usable infeed: the wheel's share of the learned size replaced"
        );
    }
}
