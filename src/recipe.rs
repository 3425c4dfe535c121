//! Part recipes: a camshaft's lobes or a crankshaft's pins with their geometry, the wheel,
//! table and program settings, tolerance bands, learning parameters and axis limits, in one
//! TOML file. Unknown keys are errors; every problem is reported at once.

use crate::core::analysis::ToleranceBand;
use crate::core::compensate::LobeLoop;
use crate::core::compensate::{AxisLimits, Feature, TableRequest, pin_nominal_lift};
use crate::core::cycle::CycleSettings;
use crate::core::fit::TableForm;
use crate::core::geometry::{CamGeometry, CrankpinGeometry, Follower};
use crate::core::learn::LearningParams;
use crate::core::lift::LiftTable;
use crate::core::measure::AssemblyLimits;
use crate::core::program::ProgramSettings;
use crate::core::speed_plan::SpeedPlanSettings;
use crate::core::turn::TurnSetup;
use crate::names::{FeatureName, PartName};
use anyhow::{Context, bail};
use serde::Deserialize;
use std::path::{Path, PathBuf};

mod check;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShaftKind {
    Camshaft,
    Crankshaft,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FollowerKind {
    Flat,
    Roller,
    Knife,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FormKind {
    G1,
    Poly,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Recipe {
    /// Part name (drawing number), for history and program comments.
    pub name: String,
    pub kind: ShaftKind,
    pub wheel: Wheel,
    #[serde(default)]
    pub table: TableSettings,
    #[serde(default)]
    pub program: ProgramSettings,
    #[serde(default)]
    pub learning: LearningParams,
    #[serde(default)]
    pub axis_limits: AxisLimits,
    /// `[speed_plan]`: a planned C speed for the finish revolution (off by default).
    #[serde(default)]
    pub speed_plan: SpeedPlanSettings,
    /// `[cycle]`: the grinding cycle's stages (none: the table-only contract).
    #[serde(default)]
    pub cycle: Option<CycleSettings>,
    #[serde(default)]
    pub lobes: Vec<Lobe>,
    #[serde(default)]
    pub pins: Vec<Pin>,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wheel {
    /// Wheel radius as last dressed, mm.
    pub radius_mm: f64,
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TableSettings {
    /// Table points per revolution, 36 to 36000.
    pub points: usize,
    pub form: FormKind,
    /// Largest deviation of a POLY table from the exact path between points, µm.
    pub poly_tolerance_um: f64,
    /// The first and last table numbers camloop may use. Each feature gets two, used in turn
    /// so the table in use is never redefined: in recipe order, (first, first + 1),
    /// (first + 2, first + 3), …; the range must hold them all.
    pub table_numbers: (u32, u32),
}

impl Default for TableSettings {
    fn default() -> Self {
        Self {
            points: 360,
            form: FormKind::Poly,
            poly_tolerance_um: 0.1,
            table_numbers: (1, 2),
        }
    }
}

impl TableSettings {
    pub fn form(&self) -> TableForm {
        match self.form {
            FormKind::G1 => TableForm::G1,
            FormKind::Poly => TableForm::Poly,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Lobe {
    /// Checked by the names' rule as the recipe is read: a bad name is an error on its line.
    pub name: FeatureName,
    /// Lift table file, relative to the recipe file.
    pub lift: PathBuf,
    pub follower: FollowerKind,
    #[serde(default)]
    pub roller_radius_mm: Option<f64>,
    pub base_radius_mm: f64,
    /// Angle of the lobe's 0° on the shaft from the shaft datum, degrees: added to the
    /// program's C offset; the gauge reads from the datum.
    #[serde(default)]
    pub phase_deg: f64,
    /// Axial station of the lobe from the shaft's Z datum, mm: where the main program moves Z.
    #[serde(default)]
    pub z_mm: f64,
    /// Tolerance bands on the profile error; none: the analysis default.
    #[serde(default)]
    pub tolerance: Vec<ToleranceBand>,
    /// Timing tolerance: largest |phase error| of the lobe against the datum, degrees.
    #[serde(default = "default_timing_tolerance_deg")]
    pub timing_tolerance_deg: f64,
    /// Largest |base radius error|, µm; none: size gets no capability index.
    #[serde(default)]
    pub size_tolerance_um: Option<f64>,
    /// Largest max |error| with nothing fitted, µm; none: it gets no capability index.
    #[serde(default)]
    pub max_error_tolerance_um: Option<f64>,
}

fn default_timing_tolerance_deg() -> f64 {
    0.05
}

fn default_stroke_tolerance_um() -> f64 {
    10.0
}

fn default_roundness_tolerance_um() -> f64 {
    2.5
}

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pin {
    /// Checked by the names' rule as the recipe is read: a bad name is an error on its line.
    pub name: FeatureName,
    pub throw_mm: f64,
    pub pin_radius_mm: f64,
    /// Index angle of the pin on the shaft from the datum, degrees (0/180/180/0 for an
    /// inline four).
    #[serde(default)]
    pub phase_deg: f64,
    /// Axial station from the shaft's Z datum, mm.
    #[serde(default)]
    pub z_mm: f64,
    #[serde(default)]
    pub tolerance: Vec<ToleranceBand>,
    /// Largest |index angle error|, degrees.
    #[serde(default = "default_timing_tolerance_deg")]
    pub index_tolerance_deg: f64,
    /// Largest |stroke error| (twice the throw error), µm.
    #[serde(default = "default_stroke_tolerance_um")]
    pub stroke_tolerance_um: f64,
    /// Largest roundness (peak to valley of the profile without its first harmonic), µm.
    #[serde(default = "default_roundness_tolerance_um")]
    pub roundness_tolerance_um: f64,
    /// Largest |diameter error|, µm; none: the diameter gets no capability index.
    #[serde(default)]
    pub diameter_tolerance_um: Option<f64>,
}

/// A recipe that could not be used: every problem found, one per line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{file}: {}", .problems.join("; "))]
pub struct RecipeError {
    pub file: String,
    pub problems: Vec<String>,
}

/// Everything the loop needs about one lobe or pin of a recipe, lift table loaded.
#[derive(Debug, Clone)]
pub struct FeatureSetup {
    /// The recipe's part name (its drawing number; no one shaft's id).
    pub part: PartName,
    /// The lobe's or pin's name in the recipe.
    pub name: FeatureName,
    /// "PART lobe NAME" or "PART pin NAME", for messages and program comments.
    pub label: String,
    pub nominal: LiftTable,
    pub feature: Feature,
    /// Program settings, with the lobe's phase added to the C offset.
    pub program: ProgramSettings,
    pub params: LearningParams,
    pub limits: AxisLimits,
    /// The recipe's `[speed_plan]`.
    pub speed_plan: SpeedPlanSettings,
    /// The recipe's `[cycle]`, checked against this feature's part.
    pub cycle: Option<CycleSettings>,
    pub request: TableRequest,
    pub table_pair: (u32, u32),
    /// With `[speed_plan] enabled`: the numbers C's table (C = f(VA)) alternates between,
    /// placed after every feature's X pair so the X numbers stay where they are.
    pub c_table_pair: Option<(u32, u32)>,
    /// With `[speed_plan] enabled` and the whole cycle: the numbers X's table over VA
    /// alternates between (the constant-speed stages keep X = f(C) in `table_pair`, so the
    /// plan's X needs a pair of its own), after every feature's C pair.
    pub plan_x_table_pair: Option<(u32, u32)>,
    pub bands: Vec<ToleranceBand>,
    /// Position in the recipe, from 1: the gauge's numeric lobe id and the grinding order.
    pub index: usize,
    /// Where the feature's 0° is on the shaft, degrees.
    pub phase_deg: f64,
    /// Axial station, mm.
    pub z_mm: f64,
    pub tolerances: FeatureTolerances,
}

/// The feature's own characteristics beside the profile bands.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub enum FeatureTolerances {
    Lobe {
        timing_deg: f64,
        size_um: Option<f64>,
        max_error_um: Option<f64>,
    },
    Pin {
        index_deg: f64,
        stroke_um: f64,
        roundness_um: f64,
        diameter_um: Option<f64>,
    },
}

/// The plan's table program in the whole cycle: the constant-speed one's name with `_P`
/// (both are on the share at once, each defining its own tables).
pub fn plan_program_name(table_program: &str) -> String {
    format!("{table_program}_P")
}

impl FeatureSetup {
    /// camloop's main program runs this feature's whole cycle with stages on the speed plan:
    /// each version is two table programs (X over C, and C and X over VA).
    pub fn plan_in_whole_cycle(&self) -> bool {
        self.plan_x_table_pair.is_some()
    }

    /// What stays fixed in this feature's loop, with the wheel the control believes in.
    pub fn lobe_loop(&self) -> LobeLoop<'_> {
        LobeLoop {
            nominal: &self.nominal,
            feature: self.feature,
            request: self.request,
            limits: &self.limits,
            params: &self.params,
        }
    }

    /// The setup of one loop turn for this feature.
    pub fn turn_setup(&self) -> TurnSetup<'_> {
        TurnSetup {
            lobe: self.lobe_loop(),
            bands: &self.bands,
            assembly: AssemblyLimits::default(),
            phase_deg: self.phase_deg,
            plan: None,
        }
    }
}

impl Recipe {
    /// Reads and checks the recipe at `path`.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read recipe {}", path.display()))?;
        Ok(Self::parse(&text, &path.display().to_string())?)
    }

    /// The lobe or pin `name` ready for the loop; lift files are read relative to `path`.
    pub fn feature_setup(&self, path: &Path, name: &str) -> anyhow::Result<FeatureSetup> {
        let Some(index) = self.feature_names().iter().position(|n| *n == name) else {
            bail!(
                "{}: no lobe or pin {name} (has: {})",
                path.display(),
                self.feature_names().join(", ")
            );
        };
        let (name, label, nominal, feature, phase_deg, z_mm, bands, tolerances) =
            if let Some(lobe) = self.lobe(name) {
                let lift_path = lobe.lift_path(path);
                let lift_text = std::fs::read_to_string(&lift_path)
                    .with_context(|| format!("cannot read lift table {}", lift_path.display()))?;
                let nominal = LiftTable::parse_csv(&lift_text, &lift_path.display().to_string())?;
                (
                    lobe.name.clone(),
                    format!("{} lobe {}", self.name, lobe.name),
                    nominal,
                    Feature::Cam(lobe.geometry(self.wheel.radius_mm)),
                    lobe.phase_deg,
                    lobe.z_mm,
                    lobe.tolerance.clone(),
                    FeatureTolerances::Lobe {
                        timing_deg: lobe.timing_tolerance_deg,
                        size_um: lobe.size_tolerance_um,
                        max_error_um: lobe.max_error_tolerance_um,
                    },
                )
            } else {
                let pin = self
                    .pin(name)
                    .expect("a feature name is a lobe's or a pin's");
                let geometry = pin.geometry(self.wheel.radius_mm);
                (
                    pin.name.clone(),
                    format!("{} pin {}", self.name, pin.name),
                    pin_nominal_lift(&geometry),
                    Feature::Pin(geometry),
                    pin.phase_deg,
                    pin.z_mm,
                    pin.tolerance.clone(),
                    FeatureTolerances::Pin {
                        index_deg: pin.index_tolerance_deg,
                        stroke_um: pin.stroke_tolerance_um,
                        roundness_um: pin.roundness_tolerance_um,
                        diameter_um: pin.diameter_tolerance_um,
                    },
                )
            };
        let mut program = self.program.clone();
        program.c_offset_deg += phase_deg;
        program.name = self.table_program_name(&name);
        if let Some(cycle) = &self.cycle {
            self.check_cycle_on(path, cycle, &feature, &nominal, &name)?;
        }
        Ok(FeatureSetup {
            part: PartName::new(&self.name).with_context(|| format!("{}: name", path.display()))?,
            name,
            label,
            nominal,
            feature,
            program,
            params: self.learning.clone(),
            limits: self.axis_limits.clone(),
            speed_plan: self.speed_plan,
            cycle: self.cycle.clone(),
            request: TableRequest {
                points: self.table.points,
                form: self.table.form(),
                poly_tolerance_um: self.table.poly_tolerance_um,
            },
            table_pair: self.table_pair(index),
            c_table_pair: self.c_table_pair(index),
            plan_x_table_pair: self.plan_x_table_pair(index),
            bands,
            index: index + 1,
            phase_deg,
            z_mm,
            tolerances,
        })
    }

    /// The cycle's checks that need the part: each stage's Q′w and the X axis with the
    /// infeed added, on feature `name`'s finished part and the wheel of the recipe.
    fn check_cycle_on(
        &self,
        path: &Path,
        cycle: &CycleSettings,
        feature: &Feature,
        nominal: &LiftTable,
        name: &str,
    ) -> anyhow::Result<()> {
        let part = feature
            .part(nominal)
            .with_context(|| format!("{}: feature {name}", path.display()))?;
        let samples = crate::core::speed_plan::ProfileSamples::new(&part)
            .with_context(|| format!("{}: feature {name}", path.display()))?;
        let ctx = crate::core::cycle::limits::CycleContext {
            samples: &samples,
            axis: &self.axis_limits,
            plan: &self.speed_plan,
            x_offset_mm: self.program.x_offset_mm,
        };
        let problems = crate::core::cycle::limits::limit_problems(cycle, &ctx);
        if problems.is_empty() {
            return Ok(());
        }
        Err(RecipeError {
            file: path.display().to_string(),
            problems: problems
                .into_iter()
                .map(|p| format!("feature {name}: {p}"))
                .collect(),
        }
        .into())
    }

    /// Every lobe or pin in recipe order (the grinding order).
    pub fn feature_setups(&self, path: &Path) -> anyhow::Result<Vec<FeatureSetup>> {
        self.feature_names()
            .iter()
            .map(|name| self.feature_setup(path, name))
            .collect()
    }

    /// The table subprogram of feature `name`: the recipe's program name, with the feature's
    /// name appended when the recipe has more than one feature.
    pub(crate) fn table_program_name(&self, name: &str) -> String {
        if self.features().count() > 1 {
            let suffix: String = name
                .chars()
                .map(|c| {
                    if c == '-' {
                        '_'
                    } else {
                        c.to_ascii_uppercase()
                    }
                })
                .collect();
            format!("{}_{suffix}", self.program.name)
        } else {
            self.program.name.clone()
        }
    }

    /// How many table numbers the features need: a pair each, two with the speed plan on,
    /// three with the plan in camloop's whole cycle (X over C and X over VA both in use).
    pub(crate) fn table_numbers_needed(&self) -> u32 {
        let pairs = match (self.speed_plan.enabled, self.whole_cycle()) {
            (false, _) => 1,
            (true, false) => 2,
            (true, true) => 3,
        };
        2 * pairs * self.features().count() as u32
    }

    /// camloop's main program runs the whole cycle (`[cycle] program = "whole"`).
    pub(crate) fn whole_cycle(&self) -> bool {
        self.cycle
            .as_ref()
            .is_some_and(|c| c.program == crate::core::cycle::CycleProgram::Whole)
    }

    /// The plan's table program of feature `name` in the whole cycle.
    pub(crate) fn plan_program_name(&self, name: &str) -> String {
        plan_program_name(&self.table_program_name(name))
    }

    /// The table numbers of the feature at `index` (from 0) in recipe order.
    fn table_pair(&self, index: usize) -> (u32, u32) {
        let first = self.table.table_numbers.0 + 2 * index as u32;
        (first, first + 1)
    }

    /// C's table numbers of the feature at `index` with the speed plan on: after all the
    /// features' X pairs.
    fn c_table_pair(&self, index: usize) -> Option<(u32, u32)> {
        let features = self.features().count() as u32;
        let first = self.table.table_numbers.0 + 2 * features + 2 * index as u32;
        self.speed_plan.enabled.then_some((first, first + 1))
    }

    /// X's table numbers over VA of the feature at `index` with the plan in the whole
    /// cycle: after all the features' C pairs.
    fn plan_x_table_pair(&self, index: usize) -> Option<(u32, u32)> {
        let features = self.features().count() as u32;
        let first = self.table.table_numbers.0 + 4 * features + 2 * index as u32;
        (self.speed_plan.enabled && self.whole_cycle()).then_some((first, first + 1))
    }

    /// Parses and checks a recipe; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Self, RecipeError> {
        let error = |problems: Vec<String>| RecipeError {
            file: file.to_string(),
            problems,
        };
        let recipe: Recipe = toml::from_str(text).map_err(|e| {
            let line = e
                .span()
                .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
            let at = line.map(|l| format!("line {l}: ")).unwrap_or_default();
            error(vec![format!("{at}{}", e.message().trim_end())])
        })?;
        let problems = recipe.problems();
        if problems.is_empty() {
            Ok(recipe)
        } else {
            Err(error(problems))
        }
    }

    pub fn lobe(&self, name: &str) -> Option<&Lobe> {
        self.lobes.iter().find(|l| l.name == name)
    }

    pub fn pin(&self, name: &str) -> Option<&Pin> {
        self.pins.iter().find(|l| l.name == name)
    }

    /// Every lobe's or pin's name, in recipe order.
    pub(crate) fn features(&self) -> impl Iterator<Item = &FeatureName> {
        self.lobes
            .iter()
            .map(|l| &l.name)
            .chain(self.pins.iter().map(|p| &p.name))
    }

    /// Names of all lobes or pins as text, for messages.
    pub(crate) fn feature_names(&self) -> Vec<&str> {
        self.features().map(FeatureName::as_str).collect()
    }
}

impl Lobe {
    pub fn geometry(&self, wheel_radius_mm: f64) -> CamGeometry {
        let follower = match self.follower {
            FollowerKind::Flat => Follower::Flat,
            FollowerKind::Knife => Follower::Knife,
            FollowerKind::Roller => Follower::Roller {
                radius_mm: self.roller_radius_mm.unwrap_or(0.0),
            },
        };
        CamGeometry {
            base_radius_mm: self.base_radius_mm,
            follower,
            wheel_radius_mm,
        }
    }

    /// The lift file's path, resolved against the recipe's folder.
    pub fn lift_path(&self, recipe_path: &Path) -> PathBuf {
        recipe_path
            .parent()
            .unwrap_or(Path::new("."))
            .join(&self.lift)
    }
}

impl Pin {
    pub fn geometry(&self, wheel_radius_mm: f64) -> CrankpinGeometry {
        CrankpinGeometry {
            throw_mm: self.throw_mm,
            pin_radius_mm: self.pin_radius_mm,
            wheel_radius_mm,
        }
    }
}
