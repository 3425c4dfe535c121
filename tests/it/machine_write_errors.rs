//! A machine's write paths say what went wrong, and the API answers each case with its own
//! code: a dressing a rule refuses is 409 `dressing_refused`, a dressing whose journal cannot
//! be written is 503 `journal_unavailable`, never reported as a refusal.

use crate::machine_support::{demo_lobe_setup, start_machine};
use camloop::service::http::{ApiCode, command_code};
use camloop::service::machine::{MachineError, MachineLoop};
use camloop::service::metrics::Metrics;
use camloop_loop::CommandError;
use std::path::Path;
use std::sync::Arc;

async fn machine(dir: &Path) -> MachineLoop {
    let metrics = Arc::new(Metrics::default());
    start_machine(dir, "DRESS1", vec![demo_lobe_setup()], metrics).await
}

#[tokio::test]
async fn a_refused_dressing_and_a_journal_failure_answer_with_different_codes() {
    let dir = tempfile::tempdir().unwrap();
    let mut m = machine(dir.path()).await;

    // A radius outside the wheel's range: refused by the rule, nothing written.
    let refused = m.dress(-1.0, None, "test").await.unwrap_err();
    assert!(
        matches!(refused, MachineError::Refused { .. }),
        "{refused:?}"
    );
    let refused = CommandError::from(refused);
    let code = command_code(&refused, ApiCode::DressingRefused);
    assert_eq!(code, ApiCode::DressingRefused);
    assert_eq!(code.status().as_u16(), 409);

    // The journal's file replaced by a folder: it cannot be opened for appending (as root
    // too, unlike a folder without write permission), so the dressing's table cannot be
    // journalled and, write-ahead, is not submitted.
    let journal = dir.path().join("state/IN1/journal.jsonl");
    if journal.exists() {
        std::fs::remove_file(&journal).unwrap();
    }
    std::fs::create_dir(&journal).unwrap();
    let failed = m.dress(249.5, None, "test").await.unwrap_err();
    assert!(matches!(failed, MachineError::Journal { .. }), "{failed:?}");
    let failed = CommandError::from(failed);
    let code = command_code(&failed, ApiCode::DressingRefused);
    assert_eq!(code, ApiCode::JournalUnavailable);
    assert_eq!(code.status().as_u16(), 503);
    assert_eq!(ApiCode::JournalUnavailable.as_str(), "journal_unavailable");
}
