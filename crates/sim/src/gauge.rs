//! The simulated in-process gauge: reads a ground part revolution after revolution with
//! Gaussian noise and optional injected faults, and hands over a [`RawMeasurement`] just
//! as a real gauge adapter would.

use super::config::{GaugeConfig, GaugeFault};
use super::ground::GroundPart;
use super::rng::SimRng;
use camloop_core::measure::{MeasurementHeader, RawMeasurement, RawSample};

/// Who the measurement belongs to, as the gauge announces it: raw labels, as a real gauge's
/// ([`camloop_core::measure::MeasurementHeader`]), so the simulator can send what a real one
/// might and the service judges them the same way.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct PartLabels {
    pub machine: String,
    pub part: String,
    pub lobe: String,
}

/// Origin string of every simulated measurement.
pub(crate) const ORIGIN: &str = "sim";

/// Reads `ground` over the configured revolutions. Samples arrive revolution by
/// revolution, angle index ascending, each the true lift plus independent noise
/// N(0, σ²), plus any fault that applies to it.
pub(crate) fn measure(
    config: &GaugeConfig,
    rng: &mut SimRng,
    ground: &GroundPart,
    labels: &PartLabels,
) -> RawMeasurement {
    let mut truth = ground.lift_on_grid(config.points_per_rev as usize);
    if config.drift_from_part > 0 && ground.part_number >= config.drift_from_part {
        let parts = f64::from(ground.part_number - config.drift_from_part + 1);
        let drift_mm = config.drift_um_per_part * 1e-3 * parts;
        truth.iter_mut().for_each(|t| *t += drift_mm);
    }
    measure_truth(config, rng, &truth, labels)
}

/// Reads `ground` with its stock still on, before the finish: as [`measure`], with the
/// in-process faults too.
pub(crate) fn measure_in_process(
    config: &GaugeConfig,
    rng: &mut SimRng,
    ground: &GroundPart,
    labels: &PartLabels,
) -> RawMeasurement {
    let mut raw = measure(config, rng, ground, labels);
    for s in &mut raw.samples {
        for fault in &config.in_process.faults {
            s.lift_mm += fault_mm(fault, s.revolution, s.angle_index);
        }
    }
    raw
}

/// Reads a part whose true lift on the gauge grid is `truth` mm (a ground part's, or a
/// master's: the nominal), with the gauge's noise and faults.
pub(crate) fn measure_truth(
    config: &GaugeConfig,
    rng: &mut SimRng,
    truth: &[f64],
    labels: &PartLabels,
) -> RawMeasurement {
    let points = config.points_per_rev;
    let sigma_mm = config.noise_sigma_um * 1e-3;
    let mut samples = Vec::with_capacity((config.revolutions * points) as usize);
    for revolution in 0..config.revolutions {
        for (angle_index, &lift) in (0..points).zip(truth) {
            let mut lift_mm = lift + sigma_mm * rng.gaussian();
            for fault in &config.faults {
                lift_mm += fault_mm(fault, revolution, angle_index);
            }
            samples.push(RawSample {
                revolution,
                angle_index,
                lift_mm,
            });
        }
    }
    RawMeasurement {
        header: MeasurementHeader {
            machine: labels.machine.clone(),
            part: labels.part.clone(),
            lobe: labels.lobe.clone(),
            revolutions: config.revolutions,
            points_per_rev: points,
        },
        samples,
        origin: ORIGIN.to_string(),
    }
}

/// What `fault` adds to the reading at (`revolution`, `angle_index`), mm.
fn fault_mm(fault: &GaugeFault, revolution: u32, angle_index: u32) -> f64 {
    match *fault {
        GaugeFault::Spike {
            revolution: r,
            angle_index: i,
            size_um,
        } if r == revolution && i == angle_index => size_um * 1e-3,
        GaugeFault::Offset {
            revolution: r,
            offset_um,
        } if r == revolution => offset_um * 1e-3,
        _ => 0.0,
    }
}
