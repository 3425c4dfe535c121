//! Packed rows chain onto the previous row of their feature, and each store handle keeps the
//! newest rows' texts to pack the next one without decoding the chain. Two handles on one
//! database (two instances of a cluster, or a restart) take turns writing one feature: a
//! handle must notice that the newest row is no longer the one it wrote, or has been
//! replaced, and every row must read back exactly from a third, fresh handle. SQLite and a
//! throwaway PostgreSQL server.

use crate::store_support;

use camloop::store::{AuditEntry, AuditResult, NewTableVersion, Role, Store, VersionStatus};
use store_support::data::{ms, sha_of};
use store_support::{f, m, tv};

/// A curve-table program whose numbers move with `v` as a learned correction moves them.
fn program(v: i64) -> String {
    let mut text = format!("; table version: v{v}\nCTABDEF(X,C,7,1)\n");
    for k in 0..360 {
        let x = 7.5 + (f64::from(k) * 0.0174).sin() * 3.0 + 3e-4 * v as f64 * f64::from(k % 7);
        text += &format!(
            "PO[C]=({k}.9160) PO[X]=({x:.4},{:.6},0.000039)\n",
            -0.002 - 1e-6 * v as f64
        );
    }
    text + "CTABEND\n"
}

fn learning(v: i64) -> String {
    let correction: Vec<f64> = (0..360)
        .map(|k| ((f64::from(k) * 0.05).cos() * v as f64 * 137.0).round() / 1000.0)
        .collect();
    serde_json::json!({"iteration": v, "wheel_radius_mm": 250.0, "correction_um": correction})
        .to_string()
}

fn state(v: i64) -> String {
    let correction: Vec<f64> = (0..360)
        .map(|k| ((f64::from(k) * 0.07).sin() * v as f64 * 91.0).round() / 1000.0)
        .collect();
    serde_json::json!({"parts": v, "learning": {"correction_um": correction}}).to_string()
}

async fn take_turns(url: &str) {
    let a = Store::connect(url).await.unwrap();
    let b = Store::connect(url).await.unwrap();
    // 40 versions: more than two chains of 16; the writer changes every 3 versions.
    for v in 1..=40_i64 {
        let store = if (v / 3) % 2 == 0 { &a } else { &b };
        let t = NewTableVersion {
            machine: m("M1"),
            lobe: f("IN1"),
            version: Some(tv(v)),
            parent_version: (v > 1).then(|| tv(v - 1)),
            table_number: 7,
            program_text: program(v),
            learning_params_json: learning(v),
            reason: format!("part {v}"),
            status: VersionStatus::Waiting {
                reason: Some("waiting".into()),
            },
            created_at: ms(v * 10),
        };
        assert_eq!(store.insert_table_version(&t).await.unwrap(), tv(v));
        // Learning snapshots: the meaning changes every 4 parts (a row is added), else the
        // newest row is replaced, by whichever handle writes this part.
        let meaning = sha_of(&format!("mode {}", v / 4));
        store
            .save_learning_snapshot(&m("M1"), &f("IN1"), &state(v), Some(&meaning), ms(v * 10))
            .await
            .unwrap();
        let other = if std::ptr::eq(store, &a) { &b } else { &a };
        let newest = other
            .load_learning_state(&m("M1"), &f("IN1"))
            .await
            .unwrap()
            .unwrap();
        assert_eq!(newest.state_json, state(v), "part {v}");
    }
    let fresh = Store::connect(url).await.unwrap();
    let versions = fresh
        .table_versions(&m("M1"), &f("IN1"), 100)
        .await
        .unwrap();
    assert_eq!(versions.len(), 40);
    for t in versions {
        let n = t.version.to_i64();
        assert_eq!(t.program_text, program(n), "v{n}");
        assert_eq!(t.learning_params_json, learning(n), "v{n}");
    }
    for v in 1..=40_i64 {
        // The snapshot of each meaning's last part is kept; the others were replaced.
        let kept = v == 40 || (v + 1) % 4 == 0;
        let exists = fresh
            .learning_state_exists(&m("M1"), &f("IN1"), &state(v), ms(v * 10))
            .await
            .unwrap();
        assert_eq!(exists, kept, "learning state of part {v}");
    }
    for s in [a, b, fresh] {
        s.close().await;
    }
}

#[tokio::test]
async fn two_handles_taking_turns_on_sqlite_read_back_exactly() {
    let dir = tempfile::tempdir().unwrap();
    take_turns(&format!(
        "sqlite://{}?mode=rwc",
        dir.path().join("c.db").display()
    ))
    .await;
}

#[tokio::test]
async fn two_handles_taking_turns_on_postgres_read_back_exactly() {
    let Some(server) = store_support::pg::start_or_skip("store_chains") else {
        return;
    };
    take_turns(&server.url()).await;
}

/// Appends made at once through two handles on one SQLite file, as `camloop user add` beside
/// a running service: each append reads the chain's newest row and then writes. Every one
/// must wait its turn for the write lock (none refused as busy), and the chain verify whole.
/// Without the immediate write transaction most runs refused one within a few appends.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_handles_appending_to_the_audit_chain_at_once_on_sqlite_both_get_through() {
    const APPENDS: i64 = 150;
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.path().display());
    let key = camloop::store::AuditKey::from_bytes([3; 32]);
    let appender = |store: Store, who: &'static str| {
        let key = key.clone();
        tokio::spawn(async move {
            for i in 0..APPENDS {
                let entry = AuditEntry {
                    at: ms(i),
                    actor: who.into(),
                    role: Role::Admin,
                    client: "local".into(),
                    action: "user.add".into(),
                    machine: None,
                    feature: None,
                    version: Some(i),
                    before: None,
                    after: None,
                    result: AuditResult::Ok,
                    reason: String::new(),
                };
                if let Err(e) = store.append_audit(&key, &entry).await {
                    return Err(format!("{who}, append {i}: {e} ({:?})", e.detail()));
                }
            }
            Ok(())
        })
    };
    let a = Store::connect(&url).await.unwrap();
    let b = Store::connect(&url).await.unwrap();
    let (ra, rb) = tokio::join!(appender(a, "a"), appender(b, "b"));
    ra.unwrap().unwrap();
    rb.unwrap().unwrap();
    let check = Store::connect(&url)
        .await
        .unwrap()
        .verify_audit(Some(&key), None)
        .await
        .unwrap();
    assert_eq!(check.rows, 2 * APPENDS as u64);
    assert_eq!(check.keyed_rows, check.rows);
    assert!(check.broken.is_empty(), "{:?}", check.broken);
}
