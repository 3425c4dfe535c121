//! The state folder's kept texts: one folder per version, stored atomically, read back
//! against the manifest's checksums, and cleaned of orphans at start.

use crate::core::ids::TableVersion;
use std::fs;
use std::path::{Path, PathBuf};

use super::error::StateError;
use super::fs::{create_temp, is_temp_name, sync_dir, write_synced};
use super::manifest::{FileRecord, History};
use super::request::ProgramFile;
use crate::core::digest::Sha256;

/// Folder of a version's kept text inside `versions_dir`: `v000042`.
pub(crate) fn version_dir(versions_dir: &Path, version: TableVersion) -> PathBuf {
    versions_dir.join(version_dir_name(version))
}

/// `v000042`: six digits so that a listing sorts by version up to 999999.
fn version_dir_name(version: TableVersion) -> String {
    format!("v{:06}", version.get())
}

fn parse_version_dir(name: &str) -> Option<TableVersion> {
    let digits = name.strip_prefix('v')?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    digits.parse().ok().and_then(TableVersion::new)
}

/// Store a version's files: a temporary folder, each file flushed, the folder flushed,
/// renamed to `v<version>`, `versions_dir` flushed. Done before the manifest line, so a
/// recorded version always has its text.
pub(crate) fn store_text(
    versions_dir: &Path,
    version: TableVersion,
    files: &[ProgramFile],
) -> Result<(), StateError> {
    let target = version_dir(versions_dir, version);
    if target.exists() {
        // An orphan from a run killed before its manifest line: never referenced.
        fs::remove_dir_all(&target).map_err(StateError::io("remove orphan", &target))?;
    }
    let ((), tmp) = create_temp(versions_dir, |p| fs::create_dir(p))
        .map_err(StateError::io("create a folder in", versions_dir))?;
    let stored = files
        .iter()
        .try_for_each(|file| {
            let path = tmp.join(&file.name);
            fs::File::create_new(&path)
                .and_then(|f| write_synced(&f, file.text.as_bytes()))
                .map_err(StateError::io("write kept text", &path))
        })
        .and_then(|()| sync_dir(&tmp).map_err(StateError::io("flush", &tmp)))
        .and_then(|()| fs::rename(&tmp, &target).map_err(StateError::io("rename", &tmp)));
    if let Err(e) = stored {
        // Best effort: a leftover temporary is removed at the next start.
        let _ = fs::remove_dir_all(&tmp);
        return Err(e);
    }
    sync_dir(versions_dir).map_err(StateError::io("flush", versions_dir))
}

/// Read a version's kept files from `dir`, each checked against its manifest SHA-256.
pub(crate) fn read_kept(dir: &Path, files: &[FileRecord]) -> Result<Vec<ProgramFile>, StateError> {
    files
        .iter()
        .map(|f| {
            let path = dir.join(&f.name);
            let bytes = fs::read(&path).map_err(StateError::io("read kept text", &path))?;
            let text = String::from_utf8(bytes)
                .ok()
                .filter(|t| Sha256::of(t.as_bytes()) == f.sha256)
                .ok_or_else(|| StateError::TextMismatch {
                    path: path.clone(),
                    expected: f.sha256,
                })?;
            Ok(ProgramFile {
                name: f.name.clone(),
                text,
            })
        })
        .collect()
}

/// Cut the manifest to its complete lines (after a kill tore the last one).
pub(crate) fn cut_manifest(path: &Path, good_len: u64) -> Result<(), StateError> {
    fs::OpenOptions::new()
        .write(true)
        .open(path)
        .and_then(|f| {
            f.set_len(good_len)?;
            f.sync_all()
        })
        .map_err(StateError::io("cut the torn last line of", path))
}

/// Remove temporaries and folders of versions that have no kept text (orphans of a kill,
/// pruned or refused versions); leave anything else alone.
pub(crate) fn clean_versions_dir(
    dir: &Path,
    history: &History,
) -> Result<Vec<PathBuf>, StateError> {
    let mut removed = Vec::new();
    let entries = fs::read_dir(dir).map_err(StateError::io("list", dir))?;
    for entry in entries {
        let entry = entry.map_err(StateError::io("list", dir))?;
        let name = entry.file_name();
        let orphan = name
            .to_str()
            .and_then(parse_version_dir)
            .is_some_and(|v| history.get(v).is_none_or(|s| !s.text_kept));
        if orphan || is_temp_name(&name) {
            let path = entry.path();
            let result = if path.is_dir() {
                fs::remove_dir_all(&path)
            } else {
                fs::remove_file(&path)
            };
            result.map_err(StateError::io("remove", &path))?;
            removed.push(path);
        }
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn version_folders_sort_and_parse_back() {
        let v = |n| TableVersion::new(n).unwrap();
        assert_eq!(version_dir_name(v(42)), "v000042");
        assert_eq!(parse_version_dir("v000042"), Some(v(42)));
        assert_eq!(parse_version_dir("v1234567"), Some(v(1_234_567)));
        assert_eq!(parse_version_dir("v000000"), None);
        assert_eq!(parse_version_dir("v"), None);
        assert_eq!(parse_version_dir("v12a"), None);
        assert_eq!(parse_version_dir("x000001"), None);
    }

    #[test]
    fn a_kept_text_that_does_not_match_its_checksum_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let files = [ProgramFile {
            name: "CAM_T1.SPF".into(),
            text: "N1 C=0 X=20\n".into(),
        }];
        let v3 = TableVersion::new(3).unwrap();
        store_text(dir.path(), v3, &files).unwrap();
        let kept = version_dir(dir.path(), v3);
        let record = |text: &str| FileRecord {
            name: "CAM_T1.SPF".into(),
            sha256: Sha256::of(text.as_bytes()),
            bytes: text.len() as u64,
        };
        assert_eq!(read_kept(&kept, &[record(&files[0].text)]).unwrap(), files);
        std::fs::write(kept.join("CAM_T1.SPF"), "N1 C=0 X=21\n").unwrap();
        let err = read_kept(&kept, &[record(&files[0].text)]).unwrap_err();
        assert!(matches!(err, StateError::TextMismatch { .. }), "{err}");
    }
}
