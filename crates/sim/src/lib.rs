//! A simulated X–C grinder and in-process gauge: a test twin for the loop and a source for
//! the demo. Pure computation (no I/O, no clock); randomness from its own seeded generator.
//!
//! # Model
//!
//! **Control.** It runs a [`CommandedTable`]: X(C) in the part frame as G1 points (X linear
//! in C between them) or POLY segments (each segment's cubic), periodic over 360°. The
//! commanded wheel-centre distance is d_cmd(c) = X(c) + x_zero. The control's X zero
//! follows the wheel radius it believes, as a tool offset would:
//! x_zero = table.x_zero_mm + (R_believed − table.wheel_radius_mm). For a table made for the
//! current wheel this is the table's own x_zero (`R + Rb` for cams, `R + r_p` for pins);
//! a table left over from before a dressing is shifted by the radius change, and is then
//! wrong only by the flank geometry, which is why the loop regenerates it.
//!
//! **Machine errors** ([`GrinderConfig`]):
//! - servo following error as a pure delay τ: X_act(c) = X(c − ω·τ), ω the C speed; with a
//!   speed plan ([`PlannedSpeed`]: C and X following a virtual axis VA at constant speed)
//!   X runs g(VA − ω_VA·τ), a lag of ≈ ω_C(c)·τ in C that follows the actual C speed at each
//!   angle (see the `plan` module);
//! - a geometric error of low harmonic order in d: Σ A_k·cos(k·c + φ_k);
//! - wheel size: the true radius R_act = R_believed + ΔR at the start, minus a wear per part;
//!   dressing (every N parts and/or after listed parts) removes the dress depth, and the
//!   control is told R_act + a dressing error (systematic plus Gaussian); the dresser
//!   reports the depth it removed as read on its scale, to a small Gaussian error, see
//!   [`SimGrinder::after_part`].
//!
//! The real wheel-centre path is W(c) = (X_act(c) + x_zero + geom(c))·u(c), u = (cos c, sin c),
//! with analytic first and second derivatives (X's are piecewise constant for G1 and the
//! cubic's for POLY). Wear within one part, thermal drift, vibration and workpiece
//! deflection are not modelled.
//!
//! **Ground part.** What a disc of radius R_act leaves as its centre runs along W, computed
//! exactly (no small-angle model; see the `envelope` module): the outline is a chain of
//! envelope pieces p = W − R_act·N (N the path's unit outward normal) of the smooth
//! stretches between table points, concave arcs of the wheel standing at table points, and
//! corners where neighbours cross. At the nose of a lobe ground from a 1° G1 table the
//! corners trim most of each piece: leaving them untrimmed would read the nose 0.9 µm too
//! high, hiding the G1 chord error. Stretches where the path turns tighter than the wheel
//! (a G1 crankpin's far side, where d < R) contribute only through their end discs. Nodes:
//! `samples_per_segment` per table segment plus corners and arcs (0.25° apart), each a
//! point with its outward normal.
//!
//! **Gauge.** It reads the outline as the part's follower: a flat face (support function
//! minus Rb), a roller of radius r (pitch radius minus Rb + r), a knife edge (polar radius
//! minus Rb); a crankpin as a flat face from the main axis (support minus (r_p − b), so the
//! nominal pin reads b·(1 + cos ψ)). Readings are interpolated from the nodes by cubic
//! Hermite in the follower's own angle (see the `ground` module), then each of
//! `revolutions` × `points_per_rev` samples gets independent Gaussian noise and any
//! configured fault. [`GroundPart::lift_on_grid`] gives the same reading without noise on
//! any grid, to judge the true profile error.
//!
//! **Defaults** ([`GrinderConfig::default`]): 30 rpm, τ = 0.45 ms (0.081° of C), harmonics
//! 2 µm (order 2) and 1 µm (order 3), ΔR = +3 µm, wear 0.1 µm/part, dressing every 50 parts
//! by 20 µm with a +2 ± 1 µm error in the radius told (the infeed read to σ = 0.2 µm),
//! gauge 4 × 360 readings with σ = 0.3 µm. On the demo lobe (8 mm lift, Rb 20 mm,
//! R 250 mm, 360-point POLY table) the uncompensated maximum profile error is 16.35 µm
//! (lag alone 13.9 µm on the flanks, harmonics alone 2.9 µm, size 3 µm), like the 16 µm of
//! the published 840D case.
//!
//! # Use
//!
//! ```
//! use camloop_core::fit::TableForm;
//! use camloop_core::geometry::{CamGeometry, Follower, Part};
//! use camloop_core::lift::{LiftCurve, LiftTable};
//! use camloop_sim::{CommandedTable, GrinderConfig, PartLabels, SimGrinder, Workpiece};
//!
//! let text = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/parts/demo-intake-lobe.csv"));
//! let lift = LiftCurve::new(&LiftTable::parse_csv(text, "demo")?);
//! let geometry = CamGeometry { base_radius_mm: 20.0, follower: Follower::Flat, wheel_radius_mm: 250.0 };
//! let mut part = Part::cam(geometry, lift)?;
//! let mut sim = SimGrinder::new(GrinderConfig::default(), Workpiece::Cam(geometry), 42)?;
//! let mut table = CommandedTable::nominal(&part, 360, TableForm::Poly)?;
//! let labels = PartLabels { machine: "m1".into(), part: "p".into(), lobe: "intake".into() };
//! for _ in 0..3 {
//!     let ground = sim.grind(&table)?;             // the part as ground
//!     let raw = sim.measure(&ground, &labels);     // what the gauge sends: 4 × 360 readings
//!     assert_eq!(raw.samples.len(), 1440);
//!     if let Some(event) = sim.after_part() {      // wear, and dressing when due
//!         part = part.with_wheel_radius(event.believed_wheel_radius_mm)?;
//!         table = CommandedTable::nominal(&part, 360, TableForm::Poly)?;
//!     }
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// No unwrap() in shipped code: bad input must become an error, not a panic (tests may).
#![warn(clippy::unwrap_used)]

pub mod cell;
mod config;
mod control;
pub mod cycle_cell;
mod delivered;
mod envelope;
pub mod frames;
mod gauge;
mod ground;
mod in_memory;
mod path;
mod plan;
mod rng;
pub mod stock;
mod table;

pub use config::{
    GaugeConfig, GaugeFault, GrinderConfig, Harmonic, InProcessGauge, ShaftErrors, StationErrors,
};
pub use control::{
    Control, ControlError, ControlFault, Coupled, CycleEvent, CycleRun, table_shape,
};
pub use delivered::DeliveryError;
pub use frames::measurement_frames;
pub use gauge::PartLabels;
pub use ground::{GroundPart, Workpiece};
pub use plan::PlannedSpeed;
use rng::SimRng;
pub use table::{CommandedTable, TableShape};

use camloop_core::measure::RawMeasurement;
use ground::Probe;
use path::MachinePath;
use plan::{CLaw, PlanLag};
use std::f64::consts::TAU;
use table::TablePath;

/// Seed offset of the dressing-error stream, so that gauge settings do not change which
/// dressing errors a seed gives.
const DRESSING_STREAM: u64 = 0x5DEE_CE66_D1CE_5EED;

/// Seed offset of the dresser's infeed-reading errors: a stream of its own, so reporting the
/// infeed or not changes no other draw of a seed.
const INFEED_STREAM: u64 = 0x1AFE_ED00_5CA1_E5ED;

/// Why the simulator refused a setting, a workpiece or a table, or could not grind it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    #[error("invalid simulator settings: {}", problems.join("; "))]
    Config { problems: Vec<String> },
    #[error("{name} = {value} is invalid: {reason}")]
    InvalidParameter {
        name: &'static str,
        value: f64,
        reason: &'static str,
    },
    #[error("table has {count} entries, at least 3 are needed")]
    TooFewTableEntries { count: usize },
    #[error("table entry {index} at c = {c_deg}° has a value that is not finite")]
    NonFiniteTableEntry { index: usize, c_deg: f64 },
    #[error("table entry {index} at c = {c_deg}° comes after {previous_deg}°: c must increase")]
    TableOrder {
        index: usize,
        c_deg: f64,
        previous_deg: f64,
    },
    #[error("table spans {span_deg}° of c, it must span less than one turn")]
    TableSpan { span_deg: f64 },
    #[error(
        "poly segment {index} runs from c = {c_start_deg}° to {c_end_deg}°: it must end after it starts"
    )]
    EmptySegment {
        index: usize,
        c_start_deg: f64,
        c_end_deg: f64,
    },
    #[error(
        "poly segment {index} ends at c = {c_end_deg}° but the next one starts at {next_start_deg}°"
    )]
    PolyGap {
        index: usize,
        c_end_deg: f64,
        next_start_deg: f64,
    },
    #[error(
        "poly segment {index} ends at x = {x_end_mm} mm (c = {c_deg}°) but the next one starts at {next_x_mm} mm"
    )]
    PolyJump {
        index: usize,
        c_deg: f64,
        x_end_mm: f64,
        next_x_mm: f64,
    },
    #[error("the planned C speed: {reason}")]
    CLaw { reason: String },
    #[error(
        "could not resolve the ground outline near c = {c_deg:.4}°: the real wheel path is too irregular"
    )]
    OutlineNotResolved { c_deg: f64 },
    #[error(
        "the ground outline does not go round once as the gauge reads it (its {what} turns by {turn_deg:.3}°)"
    )]
    NotAroundAxis { what: &'static str, turn_deg: f64 },
}

/// A dressing has happened after part `after_part`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DressingEvent {
    /// Parts ground before this dressing (1-based number of the last part).
    pub after_part: u32,
    /// Radius removed, mm.
    pub depth_mm: f64,
    /// True wheel radius after dressing, mm.
    pub wheel_radius_mm: f64,
    /// Radius the control now believes; tables should be regenerated for it, mm.
    pub believed_wheel_radius_mm: f64,
    /// Radius removed as the dresser measured it (`depth_mm` plus the reading's error), µm;
    /// `None` when the dresser does not report it.
    pub measured_infeed_um: Option<f64>,
}

/// The simulated machine and its gauge. See the module docs for the model.
#[derive(Debug, Clone)]
pub struct SimGrinder {
    config: GrinderConfig,
    workpiece: Workpiece,
    wheel_radius_mm: f64,
    believed_wheel_radius_mm: f64,
    parts_ground: u32,
    gauge_rng: SimRng,
    dressing_rng: SimRng,
    infeed_rng: SimRng,
}

impl SimGrinder {
    /// A machine with `config`'s errors set up to grind `workpiece`, whose wheel radius is
    /// the one the control believes at the start. `seed` fixes every random draw.
    pub fn new(config: GrinderConfig, workpiece: Workpiece, seed: u64) -> Result<Self, SimError> {
        let problems = config.problems();
        if !problems.is_empty() {
            return Err(SimError::Config { problems });
        }
        check_workpiece(&workpiece)?;
        let believed = workpiece.wheel_radius_mm();
        let wheel = believed + config.wheel_size_error_um * 1e-3;
        positive("true wheel radius", wheel)?;
        Ok(Self {
            config,
            workpiece,
            wheel_radius_mm: wheel,
            believed_wheel_radius_mm: believed,
            parts_ground: 0,
            gauge_rng: SimRng::new(seed),
            dressing_rng: SimRng::new(seed ^ DRESSING_STREAM),
            infeed_rng: SimRng::new(seed ^ INFEED_STREAM),
        })
    }

    pub fn config(&self) -> &GrinderConfig {
        &self.config
    }

    /// Wheel radius the control believes now, mm: what tables should be made for.
    pub fn believed_wheel_radius_mm(&self) -> f64 {
        self.believed_wheel_radius_mm
    }

    /// True wheel radius now, mm (the twin's secret, for tests and the demo).
    pub fn wheel_radius_mm(&self) -> f64 {
        self.wheel_radius_mm
    }

    /// Parts ground so far (counted by [`SimGrinder::after_part`]).
    pub fn parts_ground(&self) -> u32 {
        self.parts_ground
    }

    /// The X zero the control applies to `table`, mm (see the module docs).
    pub fn x_zero_mm(&self, table: &CommandedTable) -> f64 {
        table.x_zero_mm + (self.believed_wheel_radius_mm - table.wheel_radius_mm)
    }

    /// Grinds one part with `table` on the machine as it is now. Does not wear the wheel:
    /// call [`SimGrinder::after_part`] once the part is done.
    pub fn grind(&self, table: &CommandedTable) -> Result<GroundPart, SimError> {
        self.grind_station(table, &self.workpiece, &StationErrors::default())
    }

    /// Grinds `workpiece` (one feature of a shaft; the wheel is this grinder's) from `table`,
    /// with the feature's own errors on top of the machine's.
    pub fn grind_station(
        &self,
        table: &CommandedTable,
        workpiece: &Workpiece,
        errors: &StationErrors,
    ) -> Result<GroundPart, SimError> {
        check_workpiece(workpiece)?;
        finite("table x zero", table.x_zero_mm)?;
        positive("table wheel radius", table.wheel_radius_mm)?;
        positive("true wheel radius", self.wheel_radius_mm)?;
        let path_table = TablePath::new(&table.shape)?;
        let x_zero_mm = self.x_zero_mm(table);
        let law = table.plan.as_ref().map(CLaw::new).transpose()?;
        // With a plan the X servo's lag is a constant angle of the virtual axis.
        let (servo_lag_rad, plan) = match (&law, &table.plan) {
            (Some(law), Some(p)) => (
                0.0,
                Some(PlanLag {
                    law,
                    va_lag_rad: self.config.lag_rad_at(p.va_speed_rpm),
                }),
            ),
            _ => (self.config.lag_rad(), None),
        };
        let path = MachinePath {
            table: &path_table,
            lag_rad: servo_lag_rad + errors.lag_deg.to_radians(),
            plan,
            x_zero_mm: x_zero_mm + errors.size_um * 1e-3,
            harmonics: self
                .config
                .harmonics
                .iter()
                .map(|h| {
                    (
                        f64::from(h.order),
                        h.amplitude_um * 1e-3,
                        h.phase_deg.to_radians(),
                    )
                })
                .chain(errors.harmonics.iter().map(|h| {
                    (
                        f64::from(h.order),
                        h.amplitude_um * 1e-3,
                        h.phase_deg.to_radians(),
                    )
                }))
                .collect(),
            wheel_radius_mm: self.wheel_radius_mm,
        };
        let nodes = envelope::outline(&path, self.config.samples_per_segment)?;
        let (probe, zero_mm) = workpiece.probe();
        let part = GroundPart {
            nodes,
            probe,
            zero_mm,
            part_number: self.parts_ground + 1,
            wheel_radius_mm: self.wheel_radius_mm,
            believed_wheel_radius_mm: self.believed_wheel_radius_mm,
            x_zero_mm,
        };
        // The outline must turn once: its normal always, and the gauge's reading angle
        // too when the gauge reads along rays from the axis (roller, knife edge).
        let mut checks = vec![("normal", Probe::Flat)];
        if probe != Probe::Flat {
            checks.push(("gauge reading angle", probe));
        }
        for (what, probe) in checks {
            let turn = part.turn_rad(probe);
            if (turn - TAU).abs() > 1e-6 {
                return Err(SimError::NotAroundAxis {
                    what,
                    turn_deg: turn.to_degrees(),
                });
            }
        }
        Ok(part)
    }

    /// The gauge reading `ground` (see [`GaugeConfig`]); draws noise from the seeded stream.
    pub fn measure(&mut self, ground: &GroundPart, labels: &PartLabels) -> RawMeasurement {
        gauge::measure(&self.config.gauge, &mut self.gauge_rng, ground, labels)
    }

    /// The gauge reading `ground` before the finish, stock on, with the in-process faults
    /// too ([`config::InProcessGauge::faults`]).
    pub fn measure_in_process(
        &mut self,
        ground: &GroundPart,
        labels: &PartLabels,
    ) -> RawMeasurement {
        gauge::measure_in_process(&self.config.gauge, &mut self.gauge_rng, ground, labels)
    }

    /// The gauge reading a master part whose true lift on the gauge grid is `truth_mm` (the
    /// nominal, in the gauge's frame): a run of a type-1 gauge study. Nothing is ground.
    pub fn measure_master(&mut self, truth_mm: &[f64], labels: &PartLabels) -> RawMeasurement {
        gauge::measure_truth(&self.config.gauge, &mut self.gauge_rng, truth_mm, labels)
    }

    /// Ends a part: the wheel wears by `wear_um_per_part`, and if a dressing is due after
    /// this part (every `dress_every_parts`, or listed in `dress_at_parts`), the wheel loses
    /// `dress_depth_um` and the control is told the new radius plus the dressing error.
    /// The wheel wears by one feature's grinding; the part count and dressing wait for
    /// [`SimGrinder::after_part`] (a shaft's last feature).
    pub fn after_feature(&mut self) {
        self.wheel_radius_mm -= self.config.wear_um_per_part * 1e-3;
    }

    pub fn after_part(&mut self) -> Option<DressingEvent> {
        self.parts_ground += 1;
        let n = self.parts_ground;
        let c = &self.config;
        self.wheel_radius_mm -= c.wear_um_per_part * 1e-3;
        let scheduled = c.dress_every_parts > 0 && n.is_multiple_of(c.dress_every_parts);
        if !(scheduled || c.dress_at_parts.contains(&n)) {
            return None;
        }
        let depth_mm = c.dress_depth_um * 1e-3;
        self.wheel_radius_mm -= depth_mm;
        let error_um =
            c.dressing_error_um + c.dressing_error_sigma_um * self.dressing_rng.gaussian();
        self.believed_wheel_radius_mm = self.wheel_radius_mm + error_um * 1e-3;
        // The dresser reads its infeed (a relative move on its scale) far better than anyone
        // knows the absolute radius after it.
        let measured_infeed_um = c
            .dresser_reports_infeed
            .then(|| c.dress_depth_um + c.dresser_infeed_sigma_um * self.infeed_rng.gaussian());
        Some(DressingEvent {
            after_part: n,
            depth_mm,
            wheel_radius_mm: self.wheel_radius_mm,
            believed_wheel_radius_mm: self.believed_wheel_radius_mm,
            measured_infeed_um,
        })
    }
}

fn check_workpiece(workpiece: &Workpiece) -> Result<(), SimError> {
    match workpiece {
        Workpiece::Cam(g) => {
            positive("base radius", g.base_radius_mm)?;
            positive("wheel radius", g.wheel_radius_mm)?;
            if let camloop_core::geometry::Follower::Roller { radius_mm } = g.follower {
                positive("roller radius", radius_mm)?;
            }
        }
        Workpiece::Crankpin(g) => {
            positive("pin radius", g.pin_radius_mm)?;
            positive("wheel radius", g.wheel_radius_mm)?;
            if !(g.throw_mm.is_finite() && g.throw_mm >= 0.0) {
                return Err(SimError::InvalidParameter {
                    name: "throw",
                    value: g.throw_mm,
                    reason: "must be a finite number ≥ 0",
                });
            }
        }
    }
    Ok(())
}

fn positive(name: &'static str, value: f64) -> Result<(), SimError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SimError::InvalidParameter {
            name,
            value,
            reason: "must be a finite number > 0",
        })
    }
}

fn finite(name: &'static str, value: f64) -> Result<(), SimError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(SimError::InvalidParameter {
            name,
            value,
            reason: "must be a finite number",
        })
    }
}
