//! What a machine shares across its features: the main program that grinds them in turn, the
//! resume point on the share, and the move of a one-feature state folder from before
//! machines ground whole parts.

use super::super::journal::Pending;
use crate::core::program::{
    MainProgramSettings, RESUME_PROGRAM, Station, clear_x_mm, comment_text, render_main_program,
    render_resume_program, render_shaft_program,
};
use crate::core::speed_plan::render::{
    VaProgramSettings, VaStation, render_va_main_program, render_va_shaft_program,
};
use crate::recipe::FeatureSetup;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use tracing::{info, warn};

/// The machine's main program: its file name, text, and the table programs it calls.
#[derive(Debug)]
pub(crate) struct MainProgram {
    pub file: String,
    pub table_files: Vec<String>,
    kind: MainKind,
    /// With the whole cycle (`[cycle] program = "whole"`): the handshake's count.
    pub(super) ready: Option<super::in_process::Ready>,
}

#[derive(Debug)]
enum MainKind {
    /// At constant C speed the text depends on the recipe alone.
    Fixed(String),
    /// With the speed plan each feature's virtual-axis speed is in the text, and it changes
    /// with the feature's plan (a dressing, new limits).
    Planned(PlannedMain),
}

#[derive(Debug)]
struct PlannedMain {
    main: MainProgramSettings,
    /// Each feature's name, table settings (names and axes: the numbers come back from the
    /// table program) and station.
    stations: Vec<(crate::names::FeatureName, VaProgramSettings, f64)>,
    clear_x_mm: f64,
    /// The virtual axis' speed of the table on the share, by feature name.
    va_speeds_rpm: Mutex<BTreeMap<String, f64>>,
    /// With the whole cycle: its stages and the features it grinds (`stations` is then
    /// empty: the cycle program is made from these).
    whole: Option<Box<WholePlanned>>,
}

#[derive(Debug)]
struct WholePlanned {
    cycle: crate::core::cycle::CycleSettings,
    setups: Vec<FeatureSetup>,
}

impl MainProgram {
    /// One feature: the one-feature program (no Z, no resume). Several: the shaft program,
    /// in recipe order. The C speed is the recipe's (or the machine's override), the one the
    /// axis-limit guards checked every table at. With `[speed_plan] enabled` the programs
    /// couple C and X to the virtual axis instead (see [`Self::text_with`]).
    pub(crate) fn for_features(setups: &[FeatureSetup]) -> anyhow::Result<Self> {
        let first = setups
            .first()
            .ok_or_else(|| anyhow::anyhow!("a machine grinds at least one feature"))?;
        let mut main = MainProgramSettings {
            c_speed_rpm: first.limits.c_speed_rpm,
            ..MainProgramSettings::default()
        };
        let what = if let [only] = setups {
            format!("couples the table {} defines", only.program.name)
        } else {
            format!(
                "grinds the {} features of {} in turn",
                setups.len(),
                first.part
            )
        };
        main.comment_lines = vec![comment_text(&format!(
            "camloop {}: {what}",
            env!("CARGO_PKG_VERSION")
        ))];
        let whole = first
            .cycle
            .as_ref()
            .filter(|c| c.program == crate::core::cycle::CycleProgram::Whole);
        // The highest programmed X of any feature's nominal curve (its X offset added).
        let top_x_mm = setups
            .iter()
            .flat_map(|s| {
                let offset = s.program.x_offset_mm;
                s.nominal.lifts_mm().iter().map(move |h| h + offset)
            })
            .fold(f64::MIN, f64::max);
        let clear_x_mm = clear_x_mm(top_x_mm, whole.map_or(0.0, |c| c.lift_off_mm));
        let kind = if let Some(cycle) = whole {
            let planned = setups.iter().any(FeatureSetup::plan_in_whole_cycle);
            // Rendered once now with every plan at the grinding C speed, so what is wrong
            // with the cycle or the plan's names stops the start, not a later delivery.
            let probe: BTreeMap<String, f64> = setups
                .iter()
                .map(|s| (s.name.to_string(), first.limits.c_speed_rpm))
                .collect();
            let text = super::in_process::render_whole(&main, cycle, setups, clear_x_mm, &probe)?;
            if planned {
                MainKind::Planned(PlannedMain {
                    main: main.clone(),
                    stations: Vec::new(),
                    clear_x_mm,
                    va_speeds_rpm: Mutex::new(BTreeMap::new()),
                    whole: Some(Box::new(WholePlanned {
                        cycle: cycle.clone(),
                        setups: setups.to_vec(),
                    })),
                })
            } else {
                MainKind::Fixed(text)
            }
        } else if first.speed_plan.enabled {
            let stations = setups
                .iter()
                .map(|s| (s.name.clone(), super::planned::va_settings(s, 1, 2), s.z_mm))
                .collect();
            MainKind::Planned(PlannedMain {
                main: main.clone(),
                stations,
                clear_x_mm,
                va_speeds_rpm: Mutex::new(BTreeMap::new()),
                whole: None,
            })
        } else if let [only] = setups {
            MainKind::Fixed(render_main_program(&main, &only.program)?)
        } else {
            let stations: Vec<Station<'_>> = setups
                .iter()
                .map(|s| Station {
                    table: &s.program,
                    label: &s.name,
                    z_mm: s.z_mm,
                })
                .collect();
            MainKind::Fixed(render_shaft_program(&main, &stations, clear_x_mm)?)
        };
        Ok(Self {
            file: format!("{}.MPF", main.name),
            kind,
            table_files: setups
                .iter()
                .map(|s| format!("{}.SPF", s.program.name))
                .collect(),
            ready: whole.map(|_| super::in_process::Ready::default()),
        })
    }

    /// The text, with `feature`'s virtual-axis speed `va_speed_rpm` (the table it is about to
    /// deliver) and every other feature's as on the share. None while some feature's speed
    /// is not known yet (its table is not on the share).
    pub(crate) fn text_with(
        &self,
        feature: &str,
        va_speed_rpm: Option<f64>,
    ) -> anyhow::Result<Option<String>> {
        let planned = match &self.kind {
            MainKind::Fixed(text) => return Ok(Some(text.clone())),
            MainKind::Planned(p) => p,
        };
        let mut speeds = planned
            .va_speeds_rpm
            .lock()
            .map_err(|_| poisoned())?
            .clone();
        if let Some(v) = va_speed_rpm {
            speeds.insert(feature.to_string(), v);
        }
        if let Some(w) = &planned.whole {
            let known = w
                .setups
                .iter()
                .filter(|s| s.plan_in_whole_cycle())
                .all(|s| speeds.contains_key(s.name.as_str()));
            if !known {
                return Ok(None);
            }
            let text = super::in_process::render_whole(
                &planned.main,
                &w.cycle,
                &w.setups,
                planned.clear_x_mm,
                &speeds,
            )?;
            return Ok(Some(text));
        }
        let mut stations = Vec::with_capacity(planned.stations.len());
        for (name, settings, z_mm) in &planned.stations {
            let Some(&va_speed_rpm) = speeds.get(name.as_str()) else {
                return Ok(None);
            };
            stations.push(VaStation {
                table: settings,
                label: name,
                z_mm: *z_mm,
                va_speed_rpm,
            });
        }
        let text = if let [only] = stations.as_slice() {
            render_va_main_program(
                &planned.main.name,
                only.table,
                only.va_speed_rpm,
                planned.main.revolutions,
            )
        } else {
            render_va_shaft_program(&planned.main, &stations, planned.clear_x_mm)
        };
        Ok(Some(text?))
    }

    /// `feature`'s table with virtual-axis speed `va_speed_rpm` is on the share.
    pub(crate) fn delivered(&self, feature: &str, va_speed_rpm: f64) -> anyhow::Result<()> {
        if let MainKind::Planned(p) = &self.kind {
            p.va_speeds_rpm
                .lock()
                .map_err(|_| poisoned())?
                .insert(feature.to_string(), va_speed_rpm);
        }
        Ok(())
    }
}

fn poisoned() -> anyhow::Error {
    anyhow::anyhow!("the main program's speeds were left half-written by a failed thread")
}

/// The resume subprogram's file on the share.
pub(super) fn resume_path(share_dir: &Path) -> PathBuf {
    share_dir.join(format!("{RESUME_PROGRAM}.SPF"))
}

/// Writes the resume point atomically (a temporary beside it, flushed, renamed), so the
/// control reads the old value or the new one, never half a file.
pub(super) fn write_resume(share_dir: &Path, first_feature: usize) -> std::io::Result<()> {
    use std::io::Write as _;
    let path = resume_path(share_dir);
    let text = render_resume_program(first_feature);
    if std::fs::read_to_string(&path).ok().as_deref() == Some(text.as_str()) {
        return Ok(());
    }
    let tmp = share_dir.join(format!(
        "{}resume-{}",
        crate::share::TEMP_PREFIX,
        std::process::id()
    ));
    let mut f = std::fs::File::create(&tmp)?;
    f.write_all(text.as_bytes())?;
    f.sync_all()?;
    drop(f);
    std::fs::rename(&tmp, &path).inspect_err(|_| {
        let _ = std::fs::remove_file(&tmp);
    })?;
    crate::failpoint::crash_point("resume_written");
    Ok(())
}

/// Before machines ground whole parts, a machine's one feature kept its journal and share
/// state directly in the machine's state folder; each feature now has a folder of its own.
/// Such a folder is moved into the folder of the feature its journal names (or the only
/// feature), so the loop resumes where it was.
pub(super) fn adopt_single_feature_layout(state_dir: &Path, setups: &[FeatureSetup]) {
    let journal = state_dir.join("journal.jsonl");
    if !journal.exists() && !state_dir.join("share").is_dir() {
        return;
    }
    let named = std::fs::read_to_string(&journal).ok().and_then(|text| {
        text.lines()
            .rev()
            .find_map(|l| match serde_json::from_str::<Pending>(l) {
                Ok(Pending::Learning { lobe, .. }) => Some(lobe),
                _ => None,
            })
    });
    let feature = match (named, setups) {
        (Some(n), _) if setups.iter().any(|s| s.name == n) => n,
        (_, [only]) => only.name.clone(),
        (n, _) => {
            warn!(folder = %state_dir.display(), journal_names = ?n, "a one-feature state folder names no feature of the recipe: left where it is");
            return;
        }
    };
    let target = state_dir.join(&feature);
    if target.exists() {
        return;
    }
    let moved = (|| -> std::io::Result<()> {
        std::fs::create_dir_all(&target)?;
        for entry in std::fs::read_dir(state_dir)? {
            let entry = entry?;
            let name = entry.file_name();
            if setups.iter().any(|s| *s.name == *name) {
                continue;
            }
            std::fs::rename(entry.path(), target.join(&name))?;
        }
        Ok(())
    })();
    match moved {
        Ok(()) => {
            info!(folder = %state_dir.display(), feature = feature.as_str(), "state folder from a one-feature machine moved into the feature's folder")
        }
        Err(e) => {
            warn!(folder = %state_dir.display(), error = %e, "state folder from a one-feature machine could not be moved")
        }
    }
}
