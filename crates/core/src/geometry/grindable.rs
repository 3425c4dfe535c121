//! Grindability: the whole revolution scanned for stretches the wheel cannot grind (profile
//! through the axis, negative curvature under a flat follower, roller undercut, a concave
//! stretch tighter than the wheel), the worst one reported with its exact angle range.

use std::f64::consts::TAU;

use super::{Follower, GeometryError, Kind, Part, SCAN_STEP_DEG, pitch_curvature};

impl Part {
    /// Scans the whole revolution for stretches the wheel cannot grind and reports the first.
    pub(super) fn check_cam(&self) -> Result<(), GeometryError> {
        let Kind::Cam { geometry, lift, .. } = &self.kind else {
            return Ok(());
        };
        let (rb, big_r) = (geometry.base_radius_mm, geometry.wheel_radius_mm);
        // Each knot interval from its start knot, split into steps of at most SCAN_STEP_DEG:
        // ascending without sorting, every knot included.
        let knots = lift.knots_rad();
        let step_max = SCAN_STEP_DEG.to_radians();
        let mut samples = Vec::with_capacity(knots.len() * 11);
        for (i, &k0) in knots.iter().enumerate() {
            let k1 = knots.get(i + 1).copied().unwrap_or(knots[0] + TAU);
            let parts = ((k1 - k0) / step_max).ceil().max(1.0) as usize;
            samples.extend((0..parts).map(|j| k0 + (k1 - k0) * j as f64 / parts as f64));
        }
        // The polar profile of a roller or knife follower must stay outside the axis; a flat
        // follower only needs the wheel centre ahead of the contact line (support + R > 0),
        // which also holds for a pin that does not surround the axis.
        let offset = match geometry.follower {
            Follower::Roller { radius_mm } => radius_mm,
            Follower::Knife => 0.0,
            Follower::Flat => big_r,
        };
        for &s in &samples {
            if rb + offset + lift.eval(s).h_mm <= 0.0 {
                return Err(GeometryError::ProfileThroughAxis {
                    angle_deg: s.to_degrees(),
                });
            }
        }
        // A failing sample yields the radius to report and the error it belongs to; the
        // angle range is filled in once the whole stretch is known.
        let check = |s: f64| -> Option<(f64, GeometryError)> {
            let l = lift.eval(s);
            match geometry.follower {
                Follower::Flat => {
                    let rho = rb + l.h_mm + l.d2h_mm;
                    (rho <= 0.0).then(|| {
                        let error = GeometryError::NegativeCurvature {
                            from_deg: 0.0,
                            to_deg: 0.0,
                            min_radius_mm: rho,
                            stretches: 0,
                        };
                        (rho, error)
                    })
                }
                Follower::Roller { radius_mm } => {
                    let k = pitch_curvature(rb + radius_mm + l.h_mm, l.dh_mm, l.d2h_mm);
                    if k > 0.0 && 1.0 / k <= radius_mm {
                        return Some((
                            1.0 / k,
                            GeometryError::Undercut {
                                from_deg: 0.0,
                                to_deg: 0.0,
                                min_pitch_radius_mm: 1.0 / k,
                                roller_radius_mm: radius_mm,
                                stretches: 0,
                            },
                        ));
                    }
                    // Profile radius on a concave pitch stretch is |1/κ| + r.
                    let concave = k < 0.0 && 1.0 / -k + radius_mm < big_r;
                    concave.then(|| {
                        let r = 1.0 / -k + radius_mm;
                        (r, concave_error(r, big_r))
                    })
                }
                Follower::Knife => {
                    let k = pitch_curvature(rb + l.h_mm, l.dh_mm, l.d2h_mm);
                    (k < 0.0 && 1.0 / -k < big_r)
                        .then(|| (1.0 / -k, concave_error(1.0 / -k, big_r)))
                }
            }
        };
        worst_bad_stretch(&samples, check)
    }
}

fn concave_error(radius_mm: f64, wheel_radius_mm: f64) -> GeometryError {
    GeometryError::ConcaveTooTight {
        from_deg: 0.0,
        to_deg: 0.0,
        min_concave_radius_mm: radius_mm,
        wheel_radius_mm,
        stretches: 0,
    }
}

/// A stretch of failing samples: its smallest radius, first and last sample index, and the
/// error at that radius.
type Stretch = (f64, usize, usize, GeometryError);

/// Groups consecutive failing samples (wrapping around 360°) into stretches and returns the
/// error of the worst one (smallest radius) with its angle range and the number of stretches.
fn worst_bad_stretch(
    samples: &[f64],
    check: impl Fn(f64) -> Option<(f64, GeometryError)>,
) -> Result<(), GeometryError> {
    let flags: Vec<Option<(f64, GeometryError)>> = samples.iter().map(|&s| check(s)).collect();
    let (stretches, worst) = stretches(&flags);
    let Some((_, start, end, error)) = worst else {
        return Ok(());
    };
    // Refine both ends between the last passing and first failing sample, so the range is
    // exact to 1e-6° whatever the scan step.
    let n = samples.len();
    let unwrap = |a: f64, b: f64| if b < a { b + TAU } else { b };
    let refine = |good: f64, bad: f64| {
        let (mut good, mut bad) = (good, bad);
        while (bad - good).abs() > 1e-8 {
            let mid = 0.5 * (good + bad);
            if check(mid).is_some() {
                bad = mid
            } else {
                good = mid
            }
        }
        bad
    };
    let before = samples[(start + n - 1) % n];
    let after = samples[(end + 1) % n];
    let from = if flags[(start + n - 1) % n].is_none() {
        refine(before, unwrap(before, samples[start]))
    } else {
        samples[start]
    };
    let to = if flags[(end + 1) % n].is_none() {
        refine(unwrap(samples[end], after), samples[end])
    } else {
        samples[end]
    };
    let (from_deg, to_deg) = (
        from.to_degrees().rem_euclid(360.0),
        to.to_degrees().rem_euclid(360.0),
    );
    Err(with_range(error, from_deg, to_deg, stretches))
}

/// The number of failing stretches and the worst of them.
fn stretches(flags: &[Option<(f64, GeometryError)>]) -> (usize, Option<Stretch>) {
    let n = flags.len();
    // Walk once round from a passing sample; if none passes, the whole turn is one stretch.
    let origin = (0..n).find(|&i| flags[i].is_none()).unwrap_or(0);
    let mut stretches = 0;
    let mut worst: Option<Stretch> = None;
    let mut current: Option<Stretch> = None;
    let mut close = |run: Stretch, worst: &mut Option<Stretch>| {
        stretches += 1;
        if worst.as_ref().is_none_or(|w| run.0 < w.0) {
            *worst = Some(run);
        }
    };
    for step in 1..=n {
        let i = (origin + step) % n;
        match (&flags[i], current.as_mut()) {
            (Some((radius, error)), None) => current = Some((*radius, i, i, error.clone())),
            (Some((radius, error)), Some(run)) => {
                run.2 = i;
                if *radius < run.0 {
                    (run.0, run.3) = (*radius, error.clone());
                }
            }
            (None, _) => {
                if let Some(run) = current.take() {
                    close(run, &mut worst);
                }
            }
        }
    }
    if let Some(run) = current.take() {
        close(run, &mut worst);
    }
    (stretches, worst)
}

/// `error` with the stretch's angle range and the number of stretches filled in.
fn with_range(error: GeometryError, from_deg: f64, to_deg: f64, stretches: usize) -> GeometryError {
    match error {
        GeometryError::NegativeCurvature { min_radius_mm, .. } => {
            GeometryError::NegativeCurvature {
                from_deg,
                to_deg,
                min_radius_mm,
                stretches,
            }
        }
        GeometryError::Undercut {
            min_pitch_radius_mm,
            roller_radius_mm,
            ..
        } => GeometryError::Undercut {
            from_deg,
            to_deg,
            min_pitch_radius_mm,
            roller_radius_mm,
            stretches,
        },
        GeometryError::ConcaveTooTight {
            min_concave_radius_mm,
            wheel_radius_mm,
            ..
        } => GeometryError::ConcaveTooTight {
            from_deg,
            to_deg,
            min_concave_radius_mm,
            wheel_radius_mm,
            stretches,
        },
        other => other,
    }
}
