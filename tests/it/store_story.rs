//! The history store's story, run on SQLite and on a throwaway PostgreSQL server: machine →
//! recipe snapshot → measurements → table versions → history with filters and cursor paging
//! → learning state → dressings and events → export → retention keeps summaries. Idempotent
//! insert, refused input, replay look-ups and concurrent writers are in `store_writes`.

use crate::store_support;

use store_support::data::{LIFT_TOL_MM, all_pages, filter, measurement, ms, sha_of, table};
use store_support::{f, m, tv};

use camloop::store::{
    EventFilter, EventKind, EventLevel, FeatureKind, HistoryFilter, MeasurementId,
    MeasurementSummary, NewDressing, NewEvent, NewMeasurement, NewRecipeSnapshot, Store,
    StoreError, Verdict, VersionStatus,
};

async fn story(store: &Store) {
    assert!(store.machines().await.unwrap().is_empty());

    // Recipe snapshots: unchanged JSON reuses the newest snapshot, a change appends one.
    let snap = |lobe: &str, kind, json: &str| NewRecipeSnapshot {
        machine: m("M1"),
        part: "CAM-7".parse().unwrap(),
        lobe: f(lobe),
        kind,
        recipe_json: json.into(),
        created_at: ms(1_000),
    };
    let r1 = store
        .insert_recipe_snapshot(&snap("in1", FeatureKind::Lobe, r#"{"base_radius_mm":18}"#))
        .await
        .unwrap();
    let again = store
        .insert_recipe_snapshot(&snap("in1", FeatureKind::Lobe, r#"{"base_radius_mm":18}"#))
        .await
        .unwrap();
    assert_eq!(r1, again);
    let r2 = store
        .insert_recipe_snapshot(&snap(
            "in1",
            FeatureKind::Lobe,
            r#"{"base_radius_mm":18.5}"#,
        ))
        .await
        .unwrap();
    assert_ne!(r1, r2);
    let p1 = store
        .insert_recipe_snapshot(&snap("pin1", FeatureKind::Pin, r#"{"throw_mm":45}"#))
        .await
        .unwrap();
    let features = store.features(&m("M1")).await.unwrap();
    let seen: Vec<_> = features
        .iter()
        .map(|f| (f.lobe.as_str(), f.kind, f.recipe_snapshot))
        .collect();
    assert_eq!(
        seen,
        [
            ("in1", FeatureKind::Lobe, r2),
            ("pin1", FeatureKind::Pin, p1)
        ]
    );
    assert_eq!(features[0].recipe_json, r#"{"base_radius_mm":18.5}"#);

    // Measurements: 30 on M1/in1 (two sharing a millisecond), 10 on M1/ex1, 5 on M2/in1.
    let mut inserted: Vec<(MeasurementId, NewMeasurement)> = Vec::new();
    for n in 0..45u32 {
        let (machine, lobe) = match n {
            0..30 => ("M1", "in1"),
            30..40 => ("M1", "ex1"),
            _ => ("M2", "in1"),
        };
        // Parts 10 and 11 arrive in the same millisecond: id breaks the tie.
        let at = 10_000 + 1_000 * i64::from(n) - i64::from(n == 11) * 1_000;
        let mut m = measurement(machine, lobe, n, at);
        if n < 30 {
            m.recipe_snapshot = Some(r2);
        }
        let id = store.insert_measurement(&m).await.unwrap();
        inserted.push((id, m));
    }
    let names: Vec<_> = store
        .machines()
        .await
        .unwrap()
        .into_iter()
        .map(|m| (m.name, m.first_seen))
        .collect();
    assert_eq!(
        names,
        [(m("M1"), ms(1_000)), (m("M2"), ms(10_000 + 40_000))]
    );

    // Detail round trip: blobs within the quantisation, everything else exact.
    let (id5, m5) = &inserted[5];
    let d = store.measurement(*id5).await.unwrap().unwrap();
    assert_eq!(d.summary.id, *id5);
    assert_eq!(d.summary.part, "P-00005");
    assert_eq!(d.summary.verdict, Verdict::Pass);
    assert_eq!(d.summary.max_profile_error_um, m5.max_profile_error_um);
    assert_eq!(d.summary.recipe_snapshot, Some(r2));
    assert_eq!(d.summary.sha256, m5.sha256);
    // The report is kept as packed binary: the same JSON object (its numbers here are
    // multiples of the 0.01 quantisation step, so they come back exactly).
    let json = |t: &str| serde_json::from_str::<serde_json::Value>(t).unwrap();
    assert_eq!(json(&d.analysis_json), json(&m5.analysis_json));
    assert_eq!(d.averaged_lift_mm.len(), 36);
    for (a, b) in d.averaged_lift_mm.iter().zip(&m5.averaged_lift_mm) {
        assert!((a - b).abs() <= LIFT_TOL_MM, "averaged {a} vs {b}");
    }
    let raw = d.raw_lift_mm.as_ref().unwrap();
    assert_eq!(raw.len(), 3);
    for (ra, rb) in raw.iter().zip(&m5.raw_lift_mm) {
        for (a, b) in ra.iter().zip(rb) {
            assert!((a - b).abs() <= LIFT_TOL_MM, "raw {a} vs {b}");
        }
    }
    assert!(
        store
            .measurement(MeasurementId(-1))
            .await
            .unwrap()
            .is_none()
    );

    // History: the expectation is computed here from what was inserted, newest first.
    let expect = |keep: &dyn Fn(&NewMeasurement) -> bool| {
        let mut v: Vec<(jiff::Timestamp, MeasurementId)> = inserted
            .iter()
            .filter(|(_, m)| keep(m))
            .map(|(id, m)| (m.received_at, *id))
            .collect();
        v.sort_by(|a, b| b.cmp(a));
        v.into_iter().map(|(_, id)| id).collect::<Vec<_>>()
    };
    let ids = |v: Vec<MeasurementSummary>| v.into_iter().map(|s| s.id).collect::<Vec<_>>();

    let lobe_in1 = HistoryFilter {
        lobe: Some(f("in1")),
        ..filter("M1")
    };
    let got = ids(all_pages(store, lobe_in1.clone()).await);
    assert_eq!(got.len(), 30);
    assert_eq!(got, expect(&|m| m.machine == "M1" && m.lobe == "in1"));
    // The tie: part 11 (inserted later, higher id) comes before part 10.
    let p10 = got.iter().position(|id| *id == inserted[10].0).unwrap();
    assert_eq!(got[p10 - 1], inserted[11].0);

    let all_m1 = ids(all_pages(store, filter("M1")).await);
    assert_eq!(all_m1, expect(&|m| m.machine == "M1"));
    assert_eq!(all_m1.len(), 40);

    let fails = all_pages(
        store,
        HistoryFilter {
            verdict: Some(Verdict::Fail),
            ..lobe_in1.clone()
        },
    )
    .await;
    assert!(fails.iter().all(|s| s.verdict == Verdict::Fail));
    assert_eq!(
        ids(fails),
        expect(&|m| m.machine == "M1" && m.lobe == "in1" && m.verdict == Verdict::Fail)
    );
    assert_eq!(
        expect(&|m| m.machine == "M1" && m.lobe == "in1" && m.verdict == Verdict::Fail).len(),
        8,
        "parts 0, 4, …, 28 fail"
    );

    let window = HistoryFilter {
        since: Some(ms(15_000)),
        until: Some(ms(20_000)),
        ..lobe_in1.clone()
    };
    assert_eq!(
        ids(all_pages(store, window).await),
        expect(&|m| m.machine == "M1"
            && m.lobe == "in1"
            && (ms(15_000)..ms(20_000)).contains(&m.received_at))
    );
    let empty = store.measurement_history(&filter("nobody")).await.unwrap();
    assert!(empty.items.is_empty() && empty.next_cursor.is_none());
    let bad = HistoryFilter {
        cursor: Some("not-a-cursor".into()),
        ..filter("M1")
    };
    assert_eq!(
        store.measurement_history(&bad).await.unwrap_err().code(),
        "invalid"
    );

    // Table versions: numbered per lobe, status appended.
    assert!(
        store
            .latest_table_version(&m("M1"), &f("in1"))
            .await
            .unwrap()
            .is_none()
    );
    let v1 = store
        .insert_table_version(&table("in1", None, "CTABDEF(11)\nv1", "waiting"))
        .await
        .unwrap();
    assert_eq!(v1, tv(1));
    store
        .set_table_status(
            &m("M1"),
            &f("in1"),
            tv(1),
            &VersionStatus::Pushed {
                at: jiff::Timestamp::from_millisecond(6_000).expect("a time"),
                note: Some("pushed to share".into()),
            },
            ms(6_000),
        )
        .await
        .unwrap();
    let v2 = store
        .insert_table_version(&table("in1", Some(tv(1)), "CTABDEF(12)\nv2", "refused"))
        .await
        .unwrap();
    assert_eq!(v2, tv(2));
    assert_eq!(
        store
            .insert_table_version(&table("ex1", None, "x", "waiting"))
            .await
            .unwrap(),
        tv(1),
        "numbering is per lobe"
    );
    let latest = store
        .latest_table_version(&m("M1"), &f("in1"))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        (latest.version, latest.parent_version),
        (tv(2), Some(tv(1)))
    );
    assert_eq!(
        latest.status,
        VersionStatus::Refused {
            reason: "checks passed".into()
        }
    );
    assert_eq!(latest.sha256, sha_of("CTABDEF(12)\nv2"));
    let first = store
        .table_version(&m("M1"), &f("in1"), tv(1))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        first.status,
        VersionStatus::Pushed {
            at: jiff::Timestamp::from_millisecond(6_000).expect("a time"),
            note: Some("pushed to share".into())
        }
    );
    assert_eq!(
        (first.status.why(), first.status_at),
        ("pushed to share", ms(6_000))
    );
    assert_eq!(first.program_text, "CTABDEF(11)\nv1");
    assert_eq!(first.table_number, 11);
    assert_eq!(first.learning_params_json, r#"{"gain":0.6}"#);
    let listed: Vec<_> = store
        .table_versions(&m("M1"), &f("in1"), 10)
        .await
        .unwrap()
        .iter()
        .map(|t| t.version)
        .collect();
    assert_eq!(listed, [tv(2), tv(1)]);
    assert!(matches!(
        store
            .insert_table_version(&table("in1", Some(tv(99)), "y", "waiting"))
            .await,
        Err(StoreError::NotFound { .. })
    ));
    assert!(matches!(
        store
            .set_table_status(
                &m("M1"),
                &f("in1"),
                tv(42),
                &VersionStatus::Refused { reason: "x".into() },
                ms(1)
            )
            .await,
        Err(StoreError::NotFound { .. })
    ));
    // The share's own states are never the store's: refused, naming the state, nothing kept.
    let (m1, in1) = (m("M1"), f("in1"));
    for share_only in [
        VersionStatus::Delivering,
        VersionStatus::Superseded {
            by: camloop::core::ids::TableVersion::new(2).unwrap(),
        },
    ] {
        let e = store
            .set_table_status(&m1, &in1, tv(1), &share_only, ms(7_000))
            .await
            .unwrap_err();
        assert!(
            e.to_string().contains(share_only.name()),
            "{e} names {}",
            share_only.name()
        );
    }
    let first_again = store
        .table_version(&m1, &in1, tv(1))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(first_again.status.name(), "pushed");
    assert!(
        store
            .table_version(&m("M1"), &f("in1"), tv(3))
            .await
            .unwrap()
            .is_none()
    );

    // Learning state: newest snapshot wins.
    assert!(
        store
            .load_learning_state(&m("M1"), &f("in1"))
            .await
            .unwrap()
            .is_none()
    );
    store
        .save_learning_state(&m("M1"), &f("in1"), r#"{"k":1}"#, ms(7_000))
        .await
        .unwrap();
    store
        .save_learning_state(&m("M1"), &f("in1"), r#"{"k":2}"#, ms(8_000))
        .await
        .unwrap();
    store
        .save_learning_state(&m("M1"), &f("ex1"), r#"{"k":9}"#, ms(9_000))
        .await
        .unwrap();
    let state = store
        .load_learning_state(&m("M1"), &f("in1"))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        (state.state_json.as_str(), state.saved_at),
        (r#"{"k":2}"#, ms(8_000))
    );

    // Dressings and events.
    // The first without the dresser's infeed (as reported before it was kept), the second
    // with it.
    for (at, old_mm, new_mm, infeed) in [
        (20_000_i64, 250.0, 249.95, None),
        (30_000, 249.95, 249.9, Some(50.3)),
    ] {
        store
            .insert_dressing(&NewDressing {
                machine: m("M1"),
                at: ms(at),
                old_radius_mm: old_mm,
                new_radius_mm: new_mm,
                infeed_um: infeed,
                source: "plc".into(),
            })
            .await
            .unwrap();
    }
    let dressings = store.dressings(&m("M1"), 10).await.unwrap();
    assert_eq!(dressings.len(), 2);
    assert_eq!(dressings[0].at, ms(30_000));
    // Doubles round-trip exactly through REAL / DOUBLE PRECISION.
    assert_eq!(
        (dressings[0].old_radius_mm, dressings[0].new_radius_mm),
        (249.95, 249.9)
    );
    assert_eq!(
        (dressings[0].infeed_um, dressings[1].infeed_um),
        (Some(50.3), None)
    );
    let mut event_ids = Vec::new();
    for (at, level, kind) in [
        (1, EventLevel::Info, EventKind::ShareBack),
        (2, EventLevel::Error, EventKind::DiskFull),
        (3, EventLevel::Warn, EventKind::TableRefused),
    ] {
        let id = store
            .insert_event(&NewEvent {
                machine: m("M1"),
                at: ms(at),
                level,
                kind,
                message: format!("{} at {at}", kind.as_str()),
            })
            .await
            .unwrap();
        event_ids.push(id);
    }
    let events = store
        .events(&EventFilter {
            machine: Some(m("M1")),
            limit: 10,
            ..EventFilter::default()
        })
        .await
        .unwrap();
    let kinds: Vec<_> = events.iter().map(|e| e.kind.as_str()).collect();
    assert_eq!(kinds, ["table_refused", "disk_full", "share_back"]);
    event_ids.reverse();
    assert_eq!(events.iter().map(|e| e.id).collect::<Vec<_>>(), event_ids);
    let errors = store
        .events(&EventFilter {
            level: Some(EventLevel::Error),
            since: Some(ms(2)),
            limit: 10,
            ..EventFilter::default()
        })
        .await
        .unwrap();
    assert_eq!(errors.len(), 1);
    assert_eq!(errors[0].message, "disk_full at 2");

    // Export pages by id through everything in the window.
    let mut exported = Vec::new();
    let mut after = None;
    loop {
        let page = store
            .export(ms(0), jiff::Timestamp::MAX, after, 16)
            .await
            .unwrap();
        let Some(last) = page.last() else { break };
        after = Some(last.summary.id);
        exported.extend(page);
    }
    let mut want: Vec<_> = inserted.iter().map(|(id, _)| *id).collect();
    want.sort();
    assert_eq!(
        exported.iter().map(|d| d.summary.id).collect::<Vec<_>>(),
        want
    );

    // Retention: raw blobs before the cutoff go, summaries and averaged profiles stay.
    let cutoff = ms(20_000);
    let old = inserted
        .iter()
        .filter(|(_, m)| m.received_at < cutoff)
        .count();
    assert_eq!(
        old, 10,
        "parts 0 to 9; parts 10 and 11 arrive at the cutoff"
    );
    assert_eq!(
        store.prune_raw_older_than(cutoff).await.unwrap(),
        old as u64
    );
    assert_eq!(store.prune_raw_older_than(cutoff).await.unwrap(), 0);
    let pruned = store.measurement(*id5).await.unwrap().unwrap();
    assert!(pruned.raw_lift_mm.is_none());
    assert_eq!(pruned.averaged_lift_mm, d.averaged_lift_mm);
    assert_eq!(pruned.summary, d.summary);
    let kept = store.measurement(inserted[20].0).await.unwrap().unwrap();
    assert_eq!(kept.raw_lift_mm.map(|r| r.len()), Some(3));
    assert_eq!(all_pages(store, filter("M1")).await.len(), 40);
}

#[tokio::test]
async fn story_on_sqlite() {
    let t = store_support::sqlite().await;
    assert!(t.dir.path().join("var").join("camloop.db").is_file());
    story(&t.store).await;
}

#[tokio::test]
async fn story_on_postgres() {
    let Some(t) = store_support::postgres("story_on_postgres").await else {
        return;
    };
    story(&t.store).await;
}
