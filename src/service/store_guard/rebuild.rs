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
            let dir = version_dir(&state.join(VERSIONS_DIR), r.version);
            let Ok(texts) = r
                .files
                .iter()
                .map(|f| std::fs::read_to_string(dir.join(&f.name)))
                .collect::<Result<Vec<_>, _>>()
            else {
                continue;
            };
            let Some(program_text) = tables_of_version(&texts) else {
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

/// A version's text as the store keeps it: its table programs one after another, in the
/// order they were pushed (one, or with the speed plan in the whole cycle two: X over C,
/// then C and X over VA); the main program and the handshake's count define no table.
/// `None` when no file defines one.
fn tables_of_version(texts: &[String]) -> Option<String> {
    let tables: Vec<&str> = texts
        .iter()
        .filter(|t| !crate::core::program::table_definitions(t).is_empty())
        .map(String::as_str)
        .collect();
    (!tables.is_empty()).then(|| tables.concat())
}

#[cfg(test)]
mod tests {
    use super::tables_of_version;

    /// A version on the plan keeps both table programs, as the service stored it; the main
    /// program and the count are not part of it.
    #[test]
    fn a_versions_text_is_its_table_programs_in_order() {
        let table = |name: &str, n: u32| {
            format!("%_N_{name}_SPF\nPROC {name}\nCTABDEF(X,C,{n},1)\nC=0 X=1\nCTABEND\nM17\n")
        };
        let texts = vec![
            table("CAM_IN1", 1),
            table("CAM_IN1_P", 3),
            "%_N_MAIN_MPF\nCTAB(1)\nLEADON(X,C,CL_TNO)\nM30\n".to_string(),
            "%_N_CAMLOOP_READY_SPF\nPROC CAMLOOP_READY\nM17\n".to_string(),
        ];
        assert_eq!(
            tables_of_version(&texts),
            Some(format!("{}{}", texts[0], texts[1]))
        );
        assert_eq!(tables_of_version(&texts[2..]), None);
    }
}
