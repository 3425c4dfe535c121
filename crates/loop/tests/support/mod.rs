//! The loop tests' world without I/O: a recipe (one harmonic lobe), the parts a grinder
//! makes with the correction in force, and their times.

use camloop_core::compensate::{AxisLimits, Feature, LobeLoop, TableRequest};
use camloop_core::fit::TableForm;
use camloop_core::geometry::{CamGeometry, Follower};
use camloop_core::learn::LearningParams;
use camloop_core::lift::LiftTable;
use camloop_core::measure::{AssemblyLimits, MeasurementHeader, RawMeasurement, RawSample};
use camloop_core::turn::TurnSetup;
use camloop_loop::machine::FeatureConfig;
use jiff::Timestamp;

pub const WHEEL_MM: f64 = 250.0;

/// The recipe: a harmonic lobe (lift 1.5 (1 − cos θ) mm on a 20 mm base circle, curvature
/// radius 21.5 mm everywhere, so every table of a few µm of correction can be ground).
pub struct Recipe {
    pub nominal: LiftTable,
    pub limits: AxisLimits,
    pub params: LearningParams,
}

pub fn nominal_mm(i: u32) -> f64 {
    1.5 * (1.0 - f64::from(i).to_radians().cos())
}

impl Recipe {
    pub fn new() -> Self {
        let angles: Vec<f64> = (0..360).map(f64::from).collect();
        let lifts = (0..360).map(nominal_mm).collect();
        Self {
            nominal: LiftTable::from_points(angles, lifts, "harmonic").expect("a valid lift table"),
            limits: AxisLimits::default(),
            params: LearningParams::default(),
        }
    }

    pub fn setup(&self) -> TurnSetup<'_> {
        TurnSetup {
            lobe: LobeLoop {
                nominal: &self.nominal,
                feature: Feature::Cam(CamGeometry {
                    base_radius_mm: 20.0,
                    follower: Follower::Flat,
                    wheel_radius_mm: WHEEL_MM,
                }),
                request: TableRequest {
                    points: 360,
                    form: TableForm::G1,
                    poly_tolerance_um: 0.1,
                },
                limits: &self.limits,
                params: &self.params,
            },
            bands: &[],
            assembly: AssemblyLimits::default(),
            phase_deg: 0.0,
            plan: None,
        }
    }

    pub fn config(&self) -> FeatureConfig {
        FeatureConfig {
            feature: "IN1".parse().expect("a feature name"),
            params: self.params.clone(),
        }
    }
}

/// The part the grinder makes with the table in force: a repeatable shape error of the
/// process (8 µm at twice the cam's frequency, 3 µm at three times) plus the correction,
/// and a small error of its own per part, read on three revolutions (`torn`: the second
/// lost its samples past 100°).
pub fn grind(index: usize, correction_um: &[f64], torn: bool) -> RawMeasurement {
    let own_um = 0.4 * ((index * 7 % 5) as f64 - 2.0);
    let mut samples = Vec::new();
    for revolution in 0..3u32 {
        for i in 0..360u32 {
            if torn && revolution == 1 && i > 100 {
                continue;
            }
            let a = f64::from(i).to_radians();
            let error_um = 8.0 * (2.0 * a).cos()
                + 3.0 * (3.0 * a).sin()
                + own_um
                + correction_um[i as usize]
                + 0.05 * f64::from(revolution);
            samples.push(RawSample {
                revolution,
                angle_index: i,
                lift_mm: nominal_mm(i) + error_um / 1000.0,
            });
        }
    }
    RawMeasurement {
        header: MeasurementHeader {
            machine: "G1".into(),
            part: format!("S-{}", index + 1),
            lobe: "IN1".into(),
            revolutions: 3,
            points_per_rev: 360,
        },
        samples,
        origin: format!("gauge part {index}"),
    }
}

pub fn at(index: usize) -> Timestamp {
    Timestamp::from_second(1_700_000_000 + index as i64 * 60).expect("a time")
}
