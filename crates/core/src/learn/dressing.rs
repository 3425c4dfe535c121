//! What a wheel dressing does to the learned correction.
//!
//! A dressing changes the wheel's true radius by what the dresser removed, and the radius the
//! control believes by what it is told. The part's size moves by the difference of the two
//! changes. Two cases:
//!
//! - **The dresser measured its infeed** (the radius it removed, read on the dressing axis's
//!   scale from first contact to the end of the stroke, as a dressing cycle with contact
//!   detection reports it). Then the size step is known before the next part is ground:
//!   `(R_told,new − R_told,old) + infeed`. The whole correction moves by it and nothing
//!   needs telling apart: not the wheel's share from a station's own size error (a shaft's
//!   deflection), nor the dresser's error in the radius it tells the control. This is how
//!   the dressing miss is avoided: a relative move read on a scale is known to a fraction of
//!   a micrometre, while the absolute radius after a dressing is known to a few. (Splitting
//!   the wheel's share from the stations' by a model along Z still leaves the stations' mean
//!   in the wheel's share; a size-control gauge stopping the infeed in the cycle would take
//!   size from the loop on every part. The infeed needs neither.)
//! - **Only the new radius** (older reports). The wheel's share of the size correction is
//!   replaced by the dressing offset (see [`after_dressing`]); on a shaft the first part after
//!   the first such dressing carries the shaft's mean station error and the dresser's error.

use super::{LearningState, quantise_correction};

/// A dresser's measured infeed the loop accepts, µm: a dressing removes a few to a few
/// hundred micrometres of radius; more is a wheel change, not a dressing.
pub(crate) const DRESSER_INFEED_RANGE_UM: std::ops::RangeInclusive<f64> = 0.0..=1000.0;

/// A dresser's infeed reading that cannot be right.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error(
    "dresser infeed {0} µm is not a plausible dressing depth ({min}–{max} µm of radius)",
    min = DRESSER_INFEED_RANGE_UM.start(),
    max = DRESSER_INFEED_RANGE_UM.end()
)]
pub struct DresserInfeedError(pub f64);

/// Checks a dresser's measured infeed from the control's feed, a dropped report or the API.
pub fn check_dresser_infeed(infeed_um: f64) -> Result<f64, DresserInfeedError> {
    if DRESSER_INFEED_RANGE_UM.contains(&infeed_um) {
        Ok(infeed_um)
    } else {
        Err(DresserInfeedError(infeed_um))
    }
}

/// How much larger the next part would come out with the same correction, µm, after a
/// dressing that took the believed radius from `old_radius_mm` to `new_radius_mm` while the
/// dresser removed `infeed_um` of the true radius: the believed radius less the true one
/// (what grinds a part oversize) changes by `(new − old) + infeed`.
pub fn dressing_size_step_um(old_radius_mm: f64, new_radius_mm: f64, infeed_um: f64) -> f64 {
    (new_radius_mm - old_radius_mm) * 1000.0 + infeed_um
}

/// After a dressing whose size step the dresser's infeed tells (see
/// [`dressing_size_step_um`]): the whole correction (and the best one kept) moves by
/// −`size_step_um`, so the next part comes out as the last did but for the wear and what the
/// infeed reading missed. The size disturbance of the last part moves by the step too, so the
/// wear rate carries on through the dressing; the next part's size error is learned whole and
/// not as drift (it is the infeed reading's error). The dressing offset is left alone: it is
/// what dressings without an infeed start from.
pub fn after_measured_dressing(state: &mut LearningState, size_step_um: f64) {
    let shift = -size_step_um;
    state.correction_um.iter_mut().for_each(|u| *u += shift);
    quantise_correction(&mut state.correction_um, f64::INFINITY);
    if let Some(best) = state.best.as_mut() {
        best.correction_um.iter_mut().for_each(|u| *u += shift);
        quantise_correction(&mut best.correction_um, f64::INFINITY);
    }
    if let Some(d) = state.last_size_disturbance_um.as_mut() {
        *d += size_step_um;
    }
    state.dressing_measured = true;
}

/// After a wheel dressing the control gets a new wheel radius, which replaces everything the
/// loop learned about the wheel's size (the initial radius error and the wear since). So the
/// part of the size correction that was the wheel's, `wheel_size_um` (for one feature, its
/// whole size correction; for a shaft, what all its features have in common: a lobe's own
/// size error, such as the shaft's deflection at its station, is not the wheel's), is
/// replaced by the dressing offset (what the previous dressings needed: a dresser's
/// systematic error), and the shape is kept. The error history restarts so the size step
/// after dressing is not taken for divergence, and the next step learns that step into the
/// offset rather than into the wear rate. Used when the dresser did not report its infeed
/// (see [`after_measured_dressing`] when it did).
pub fn after_dressing(state: &mut LearningState, wheel_size_um: f64) {
    let shift = state.dressing_offset_um - wheel_size_um;
    state.correction_um.iter_mut().for_each(|u| *u += shift);
    quantise_correction(&mut state.correction_um, f64::INFINITY);
    if let Some(best) = state.best.as_mut() {
        best.correction_um.iter_mut().for_each(|u| *u += shift);
        quantise_correction(&mut best.correction_um, f64::INFINITY);
    }
    state.recent_max_error_um.clear();
    state.dressed = true;
}

/// The size part (order 0, the mean) of a state's correction, µm.
pub fn size_correction_um(state: &LearningState) -> f64 {
    state.correction_um.iter().sum::<f64>() / state.correction_um.len().max(1) as f64
}
