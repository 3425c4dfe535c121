//! The version index rebuilt from the shares when a new database is accepted: every version
//! whose text the share's state folder still keeps goes into the store under its own number,
//! with its reason and status, so history, diffs and program downloads continue where the
//! share is. (Versions whose text was pruned are only counted; their correction was never in
//! the manifest, so a rollback to a rebuilt version is refused with a reason.)

use super::MachineExpectation;
use crate::share::{MANIFEST_FILE, VERSIONS_DIR, VersionStatus, load_manifest, version_dir};
use crate::store::{NewTableVersion, Store, StoreError};

/// Inserts the kept versions the store lacks; returns how many went in.
pub(super) async fn rebuild_versions(
    store: &Store,
    expectations: &[MachineExpectation],
) -> Result<u64, StoreError> {
    let mut rebuilt = 0;
    for e in expectations {
        let state = e.state_dir.join("share");
        let Ok(loaded) = load_manifest(&state.join(MANIFEST_FILE)) else {
            continue;
        };
        for v in loaded.history.versions().iter().filter(|v| v.text_kept) {
            let r = &v.record;
            let version = r.version;
            if store
                .table_version(&e.machine, &e.lobe, version)
                .await?
                .is_some()
            {
                continue;
            }
            // The table program is the first file of a version (the main program goes last).
            let Some(file) = r.files.first() else {
                continue;
            };
            let dir = version_dir(&state.join(VERSIONS_DIR), r.version);
            let Ok(program_text) = std::fs::read_to_string(dir.join(&file.name)) else {
                continue;
            };
            // The share's own states (delivering, superseded) are waiting to the store.
            let status = match &v.status {
                VersionStatus::Pushed { .. } => {
                    VersionStatus::pushed_at(r.created_at, "pushed (from the share's manifest)")
                }
                VersionStatus::Refused { .. } => VersionStatus::Refused {
                    reason: "refused (from the share's manifest)".into(),
                },
                _ => VersionStatus::Waiting {
                    reason: Some("not confirmed on the share (from its manifest)".into()),
                },
            };
            let t = NewTableVersion {
                machine: crate::names::MachineName::new(&e.machine)
                    .map_err(|err| StoreError::invalid("machine", err.to_string()))?,
                lobe: e.lobe.clone(),
                version: Some(version),
                parent_version: None,
                table_number: r.table_number,
                program_text,
                learning_params_json: r.learning.to_string(),
                reason: format!("{} (rebuilt from the share)", r.reason),
                status,
                created_at: r.created_at,
            };
            store.insert_table_version(&t).await?;
            rebuilt += 1;
        }
    }
    Ok(rebuilt)
}
