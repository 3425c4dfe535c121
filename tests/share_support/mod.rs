//! Helpers shared by the share tests: temporary share and state folders, a fake clock,
//! real curve-table programs.

use std::path::{Path, PathBuf};

use camloop::core::program::{ProgramSettings, render_g1_table};
use camloop::core::table::TablePoint;
use camloop::share::{
    Clock, OpenReport, ProgramFile, PushRequest, RealFs, Share, ShareConfig, ShareFs,
};

/// A share folder and a state folder side by side in one temporary folder.
pub struct Dirs {
    pub root: tempfile::TempDir,
    pub share: PathBuf,
    pub state: PathBuf,
}

pub fn dirs() -> Dirs {
    let root = tempfile::tempdir().unwrap();
    let share = root.path().join("nc-share");
    let state = root.path().join("state");
    std::fs::create_dir(&share).unwrap();
    Dirs { root, share, state }
}

pub fn config(dirs: &Dirs, keep_versions: usize) -> ShareConfig {
    ShareConfig {
        share_dir: dirs.share.clone(),
        state_dir: dirs.state.clone(),
        table_pair: (1, 2),
        keep_versions,
    }
}

/// A clock starting at 2023-11-14T22:13:20Z that advances 1 s per reading.
pub fn clock() -> Clock {
    let mut now = jiff::Timestamp::from_second(1_700_000_000).unwrap();
    Box::new(move || {
        now += jiff::SignedDuration::from_secs(1);
        now
    })
}

pub fn open(dirs: &Dirs, keep_versions: usize) -> (Share, OpenReport) {
    open_with(dirs, keep_versions, Box::new(RealFs))
}

pub fn open_with(dirs: &Dirs, keep_versions: usize, fs: Box<dyn ShareFs>) -> (Share, OpenReport) {
    Share::open(config(dirs, keep_versions), fs, clock()).unwrap()
}

/// A real 360-point G1 curve table `CAM_T<table>` whose X values depend on `tag`, so that
/// versions differ: X = 20 + (2 + tag/1000) · sin C mm.
pub fn table_program(table: u32, tag: u32) -> ProgramFile {
    let points: Vec<TablePoint> = (0..360)
        .map(|i| {
            let c_deg = f64::from(i);
            let x_mm = 20.0 + (2.0 + f64::from(tag) / 1000.0) * c_deg.to_radians().sin();
            TablePoint {
                c_deg,
                d_mm: x_mm,
                x_mm,
            }
        })
        .collect();
    let settings = ProgramSettings {
        name: format!("CAM_T{table}"),
        table_number: table,
        ..ProgramSettings::default()
    };
    ProgramFile {
        name: format!("CAM_T{table}.SPF"),
        text: render_g1_table(&points, &settings).unwrap(),
    }
}

/// The SHA-256 standing for measurement `m<tag>`, as the service names a measurement.
pub fn measurement(tag: u32) -> camloop::digest::Sha256 {
    camloop::digest::Sha256::of(format!("m{tag}").as_bytes())
}

/// A request for the next version: one table program with the share's next table number.
pub fn next_request(share: &Share, tag: u32) -> PushRequest {
    let table = share.next_table_number();
    PushRequest {
        files: vec![table_program(table, tag)],
        table_number: table,
        reason: format!("learned from measurement m{tag}"),
        measurement_id: Some(measurement(tag)),
        learning: serde_json::json!({ "gain": 0.5, "tag": tag }),
        rollback_of: None,
        created_at: jiff::Timestamp::from_millisecond(1_700_000_000_000 + i64::from(tag)).unwrap(),
    }
}

/// File names in a folder, sorted.
pub fn names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    names
}
