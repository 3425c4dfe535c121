//! Simulator settings: the machine's errors, the wheel's life (wear, dressing), the envelope
//! sampling and the gauge. Every field has a default; the defaults give an uncompensated
//! maximum profile error of about 16 µm on the demo lobe, like the published 840D case.

use serde::{Deserialize, Serialize};

/// Everything the simulated grinder and gauge can be told. Deserialises from a TOML table
/// (unknown keys are errors); missing keys take the defaults below.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GrinderConfig {
    /// Constant C speed while grinding, rpm (revolutions per minute). Default 30.
    pub c_speed_rpm: f64,
    /// X servo following error as a pure time delay, ms: the actual X at C = c is the
    /// commanded X at c − ω·τ. Default 0.45 ms (0.081° at 30 rpm).
    pub servo_lag_ms: f64,
    /// Geometric error of the machine, added to the wheel-centre distance as
    /// Σ A·cos(k·c + φ). Default: order 2, 2 µm at 30°; order 3, 1 µm at 100°.
    pub harmonics: Vec<Harmonic>,
    /// Initial wheel-size error: true radius minus the radius the control believes, µm
    /// (positive: the wheel is bigger than believed and grinds the part smaller). Default 3.
    pub wheel_size_error_um: f64,
    /// Radius the wheel loses per part ground, µm. Default 0.1.
    pub wear_um_per_part: f64,
    /// Dress after every this many parts (0: never on a schedule). Default 50.
    pub dress_every_parts: u32,
    /// Also dress after these part numbers (1-based count of parts ground). Default none.
    pub dress_at_parts: Vec<u32>,
    /// Radius removed by one dressing, µm. Default 20.
    pub dress_depth_um: f64,
    /// Systematic error of the radius the control is told after dressing (told minus true),
    /// µm. Default 2.
    pub dressing_error_um: f64,
    /// Standard deviation of a random part of that error, drawn per dressing, µm. Default 1.
    pub dressing_error_sigma_um: f64,
    /// The dresser reports its measured infeed with each dressing: the radius it removed, read
    /// on the dressing axis's scale from first contact to the end of the stroke. Default true.
    pub dresser_reports_infeed: bool,
    /// Standard deviation of that reading's error (true radius removed less reported), drawn
    /// per dressing, µm. Default 0.2 (scale resolution, contact detection, the roll's wear).
    pub dresser_infeed_sigma_um: f64,
    /// Envelope samples per table segment (the part between two table points). Default 16.
    pub samples_per_segment: usize,
    pub gauge: GaugeConfig,
    /// Errors that differ from feature to feature of a whole shaft.
    pub shaft: ShaftErrors,
    /// The wheel head and the grinding forces of a whole cycle (see the `stock` module).
    /// Boxed: the service's gauge settings hold a `GrinderConfig` beside far smaller ones.
    pub stock: Box<crate::stock::StockModel>,
}

/// How the features of one shaft differ: the shaft bends and twists along Z under the
/// grinding force, and each lobe has a harmonic error of its own. Defaults: 0.8 µm oversize
/// and 0.004° more lag per 100 mm of Z, a ±0.6 µm order-2 harmonic varying by feature, and a
/// gauge that never mixes up lobes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ShaftErrors {
    /// Size error (part oversize) growing along Z, µm per 100 mm of Z (deflection).
    pub size_um_per_100mm: f64,
    /// Phase lag growing along Z, degrees per 100 mm of Z (torsion: the shaft is driven at
    /// its Z = 0 end).
    pub lag_deg_per_100mm: f64,
    /// Amplitude of a feature's own order-2 error, µm: feature k gets
    /// `spread · sin(1.7·k)` at a phase of 40°·k, so no two lobes are alike.
    pub harmonic_spread_um: f64,
    /// Every this many features gauged, the gauge labels the measurement with the next lobe
    /// of the shaft instead (0: never).
    pub wrong_lobe_every: u32,
    /// Every this many features gauged, the gauge labels it with a lobe the shaft lacks
    /// (0: never).
    pub unknown_lobe_every: u32,
}

impl Default for ShaftErrors {
    fn default() -> Self {
        Self {
            size_um_per_100mm: 0.8,
            lag_deg_per_100mm: 0.004,
            harmonic_spread_um: 0.6,
            wrong_lobe_every: 0,
            unknown_lobe_every: 0,
        }
    }
}

/// One feature's own errors on top of the machine's.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StationErrors {
    /// Part oversize, µm.
    pub size_um: f64,
    /// Extra lag, degrees.
    pub lag_deg: f64,
    pub harmonics: Vec<Harmonic>,
}

impl ShaftErrors {
    /// The errors of feature `index` (from 1) at station `z_mm`.
    pub fn station(&self, index: usize, z_mm: f64) -> StationErrors {
        let k = index as f64;
        StationErrors {
            size_um: self.size_um_per_100mm * z_mm / 100.0,
            lag_deg: self.lag_deg_per_100mm * z_mm / 100.0,
            harmonics: vec![Harmonic {
                order: 2,
                amplitude_um: self.harmonic_spread_um * (1.7 * k).sin(),
                phase_deg: 40.0 * k,
            }],
        }
    }
}

/// One harmonic of the machine's geometric error in the wheel-centre distance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Harmonic {
    /// Order k (cycles per revolution of C), ≥ 1.
    pub order: u32,
    pub amplitude_um: f64,
    pub phase_deg: f64,
}

/// The in-process gauge.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaugeConfig {
    /// Revolutions measured per part. Default 4 (the analysis wants at least 3; fewer can be
    /// configured to test that it refuses them).
    pub revolutions: u32,
    /// Readings per revolution, index 0 at 0° of the part frame. Default 360.
    pub points_per_rev: u32,
    /// Standard deviation of the independent Gaussian noise on every reading, µm. Default 0.3.
    pub noise_sigma_um: f64,
    /// Faults injected into every measurement (for tests of the analysis). Default none.
    pub faults: Vec<GaugeFault>,
    /// A type-1 gauge study on request: before shaft `master_before_part` (from 1; 0 never)
    /// the gauge measures the master part (the nominal) this many times per feature, as part
    /// `MASTER`. Default 0: no master runs.
    pub master_runs: u32,
    /// See `master_runs`. Default 0.
    pub master_before_part: u64,
    /// An injected drift, to prove the control charts: from part (shaft) `drift_from_part`
    /// on (0: never) every reading grows by this much per part, µm (a gauge warming up).
    /// Default 0.
    pub drift_um_per_part: f64,
    /// See `drift_um_per_part`. Default 0.
    pub drift_from_part: u32,
    /// The readings before the finish, stock on (`[gauge.in_process]`).
    pub in_process: InProcessGauge,
}

/// What differs when the gauge reads a part before its finish.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InProcessGauge {
    /// Faults injected into the in-process readings only (a probe that slips on a part with
    /// its stock on), on top of the gauge's `faults`. Default none.
    pub faults: Vec<GaugeFault>,
    /// How long an in-process reading takes from the gauge to camloop (the gauge's own
    /// evaluation and transfer), s: past the cycle's `handshake_timeout_s` the control has
    /// ground the finish with the table in force before camloop has the reading. At most an
    /// hour. Default 0.
    pub handover_s: f64,
}

/// A deliberate gauge fault, to check that the analysis notices it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum GaugeFault {
    /// One reading off by `size_um`.
    Spike {
        revolution: u32,
        angle_index: u32,
        size_um: f64,
    },
    /// A whole revolution off by `offset_um` (a probe that slipped).
    Offset { revolution: u32, offset_um: f64 },
}

impl Default for GrinderConfig {
    fn default() -> Self {
        Self {
            c_speed_rpm: 30.0,
            servo_lag_ms: 0.45,
            harmonics: vec![
                Harmonic {
                    order: 2,
                    amplitude_um: 2.0,
                    phase_deg: 30.0,
                },
                Harmonic {
                    order: 3,
                    amplitude_um: 1.0,
                    phase_deg: 100.0,
                },
            ],
            wheel_size_error_um: 3.0,
            wear_um_per_part: 0.1,
            dress_every_parts: 50,
            dress_at_parts: Vec::new(),
            dress_depth_um: 20.0,
            dressing_error_um: 2.0,
            dressing_error_sigma_um: 1.0,
            dresser_reports_infeed: true,
            dresser_infeed_sigma_um: 0.2,
            samples_per_segment: 16,
            gauge: GaugeConfig::default(),
            shaft: ShaftErrors::default(),
            stock: Box::default(),
        }
    }
}

impl Default for GaugeConfig {
    fn default() -> Self {
        Self {
            revolutions: 4,
            points_per_rev: 360,
            noise_sigma_um: 0.3,
            faults: Vec::new(),
            master_runs: 0,
            master_before_part: 0,
            drift_um_per_part: 0.0,
            drift_from_part: 0,
            in_process: InProcessGauge::default(),
        }
    }
}

impl GrinderConfig {
    /// A machine without errors: no lag, no harmonics, exact wheel size, no wear, no
    /// dressing, a noiseless gauge. Other settings (C speed, sampling, gauge grid) default.
    pub fn perfect() -> Self {
        Self {
            servo_lag_ms: 0.0,
            harmonics: Vec::new(),
            wheel_size_error_um: 0.0,
            wear_um_per_part: 0.0,
            dress_every_parts: 0,
            dress_depth_um: 0.0,
            dressing_error_um: 0.0,
            dressing_error_sigma_um: 0.0,
            dresser_infeed_sigma_um: 0.0,
            gauge: GaugeConfig {
                noise_sigma_um: 0.0,
                ..GaugeConfig::default()
            },
            shaft: ShaftErrors {
                size_um_per_100mm: 0.0,
                lag_deg_per_100mm: 0.0,
                harmonic_spread_um: 0.0,
                ..ShaftErrors::default()
            },
            ..Self::default()
        }
    }

    /// The servo lag as an angle of C, radians: ω·τ.
    pub fn lag_rad(&self) -> f64 {
        self.lag_rad_at(self.c_speed_rpm)
    }

    /// The servo lag as an angle of an axis turning at `speed_rpm`, radians.
    pub(crate) fn lag_rad_at(&self, speed_rpm: f64) -> f64 {
        (speed_rpm * 6.0 * self.servo_lag_ms * 1e-3).to_radians()
    }

    /// Every problem with the settings, each naming its field; empty when all is well.
    pub fn problems(&self) -> Vec<String> {
        let mut p = Problems(Vec::new());
        self.check_numbers(&mut p);
        for (i, h) in self.harmonics.iter().enumerate() {
            p.need(
                h.order >= 1,
                &format!("harmonics[{i}].order"),
                h.order as f64,
                "must be ≥ 1",
            );
            p.need(
                h.amplitude_um.is_finite(),
                &format!("harmonics[{i}].amplitude_um"),
                h.amplitude_um,
                "must be a finite number",
            );
            p.need(
                h.phase_deg.is_finite(),
                &format!("harmonics[{i}].phase_deg"),
                h.phase_deg,
                "must be a finite number",
            );
        }
        self.check_gauge(&mut p);
        p.0.extend(self.stock.problems());
        p.0
    }

    /// The machine's own numbers: speeds, lags, wear, dressing and shaft errors, sampling.
    fn check_numbers(&self, p: &mut Problems) {
        p.need(
            self.c_speed_rpm.is_finite() && self.c_speed_rpm > 0.0,
            "c_speed_rpm",
            self.c_speed_rpm,
            "must be a finite number > 0",
        );
        for (name, value) in [
            ("servo_lag_ms", self.servo_lag_ms),
            ("wear_um_per_part", self.wear_um_per_part),
            ("dress_depth_um", self.dress_depth_um),
            ("dressing_error_sigma_um", self.dressing_error_sigma_um),
            ("dresser_infeed_sigma_um", self.dresser_infeed_sigma_um),
            ("gauge.noise_sigma_um", self.gauge.noise_sigma_um),
        ] {
            p.need(
                value.is_finite() && value >= 0.0,
                name,
                value,
                "must be a finite number ≥ 0",
            );
        }
        for (name, value) in [
            ("wheel_size_error_um", self.wheel_size_error_um),
            ("dressing_error_um", self.dressing_error_um),
            ("shaft.size_um_per_100mm", self.shaft.size_um_per_100mm),
            ("shaft.lag_deg_per_100mm", self.shaft.lag_deg_per_100mm),
            ("shaft.harmonic_spread_um", self.shaft.harmonic_spread_um),
        ] {
            p.need(value.is_finite(), name, value, "must be a finite number");
        }
        let handover_s = self.gauge.in_process.handover_s;
        p.need(
            (0.0..=3600.0).contains(&handover_s),
            "gauge.in_process.handover_s",
            handover_s,
            "must be within 0..=3600",
        );
        p.need(
            (2..=1000).contains(&self.samples_per_segment),
            "samples_per_segment",
            self.samples_per_segment as f64,
            "must be within 2..=1000",
        );
    }

    /// The gauge's revolutions and grid, and that every injected fault falls on them.
    fn check_gauge(&self, p: &mut Problems) {
        let g = &self.gauge;
        p.need(
            g.revolutions >= 1,
            "gauge.revolutions",
            g.revolutions as f64,
            "must be ≥ 1",
        );
        p.need(
            (36..=36_000).contains(&g.points_per_rev),
            "gauge.points_per_rev",
            g.points_per_rev as f64,
            "must be within 36..=36000",
        );
        for (list, faults) in [
            ("faults", &g.faults),
            ("in_process.faults", &g.in_process.faults),
        ] {
            check_faults(p, g, list, faults);
        }
    }
}

/// Every fault of `gauge.<list>` falls on the gauge's revolutions and grid, with a size.
fn check_faults(p: &mut Problems, g: &GaugeConfig, list: &str, faults: &[GaugeFault]) {
    for (i, fault) in faults.iter().enumerate() {
        let (revolution, size) = match fault {
            GaugeFault::Spike {
                revolution,
                angle_index,
                size_um,
            } => {
                p.need(
                    *angle_index < g.points_per_rev,
                    &format!("gauge.{list}[{i}].angle_index"),
                    *angle_index as f64,
                    "must be below gauge.points_per_rev",
                );
                (*revolution, *size_um)
            }
            GaugeFault::Offset {
                revolution,
                offset_um,
            } => (*revolution, *offset_um),
        };
        p.need(
            revolution < g.revolutions,
            &format!("gauge.{list}[{i}].revolution"),
            revolution as f64,
            "must be below gauge.revolutions",
        );
        p.need(
            size.is_finite(),
            &format!("gauge.{list}[{i}] size"),
            size,
            "must be a finite number",
        );
    }
}

/// Problems found so far, each as `field = value rule`.
struct Problems(Vec<String>);

impl Problems {
    fn need(&mut self, ok: bool, field: &str, value: f64, rule: &str) {
        if !ok {
            self.0.push(format!("{field} = {value} {rule}"));
        }
    }
}
