//! What a machine shares across its features: the main program that grinds them in turn, the
//! resume point on the share, and the move of a one-feature state folder from before
//! machines ground whole parts.

use super::super::journal::Pending;
use crate::core::program::{
    MainProgramSettings, RESUME_PROGRAM, Station, comment_text, render_main_program,
    render_resume_program, render_shaft_program,
};
use crate::recipe::FeatureSetup;
use std::path::{Path, PathBuf};
use tracing::{info, warn};

/// X clearance above the highest nominal lift before Z moves, mm.
const CLEARANCE_MM: f64 = 5.0;

/// The machine's main program: its file name, text, and the table programs it calls.
#[derive(Debug, Clone)]
pub(crate) struct MainProgram {
    pub file: String,
    pub text: String,
    pub table_files: Vec<String>,
}

impl MainProgram {
    /// One feature: the one-feature program (no Z, no resume). Several: the shaft program,
    /// in recipe order. The C speed is the recipe's (or the machine's override), the one the
    /// axis-limit guards checked every table at.
    pub(crate) fn for_features(setups: &[FeatureSetup]) -> anyhow::Result<Self> {
        let first = setups
            .first()
            .ok_or_else(|| anyhow::anyhow!("a machine grinds at least one feature"))?;
        let mut main = MainProgramSettings {
            c_speed_rpm: first.limits.c_speed_rpm,
            ..MainProgramSettings::default()
        };
        let text = if let [only] = setups {
            main.comment_lines = vec![comment_text(&format!(
                "camloop {}: couples the table {} defines",
                env!("CARGO_PKG_VERSION"),
                only.program.name
            ))];
            render_main_program(&main, &only.program)?
        } else {
            main.comment_lines = vec![comment_text(&format!(
                "camloop {}: grinds the {} features of {} in turn",
                env!("CARGO_PKG_VERSION"),
                setups.len(),
                first.part
            ))];
            let stations: Vec<Station<'_>> = setups
                .iter()
                .map(|s| Station {
                    table: &s.program,
                    label: &s.name,
                    z_mm: s.z_mm,
                })
                .collect();
            let clear_x_mm = setups
                .iter()
                .flat_map(|s| s.nominal.lifts_mm().iter().copied())
                .fold(0.0f64, f64::max)
                + CLEARANCE_MM;
            render_shaft_program(&main, &stations, clear_x_mm)?
        };
        Ok(Self {
            file: format!("{}.MPF", main.name),
            text,
            table_files: setups
                .iter()
                .map(|s| format!("{}.SPF", s.program.name))
                .collect(),
        })
    }
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
            info!(folder = %state_dir.display(), feature, "state folder from a one-feature machine moved into the feature's folder")
        }
        Err(e) => {
            warn!(folder = %state_dir.display(), error = %e, "state folder from a one-feature machine could not be moved")
        }
    }
}
