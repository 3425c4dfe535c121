//! Pushes on the real file system (temporary folders): content, manifest, checksums, table
//! alternation, refusals, rollback, pruning, and what a new start cleans up.

use crate::share_support;

use camloop::share::{
    MANIFEST_FILE, ProgramFile, PushError, PushRequest, StateError, Submitted, VERSIONS_DIR,
    VersionStatus, load_manifest,
};
use sha2::{Digest, Sha256};
use share_support::{dirs, names, next_request, open, table_program};

/// SHA-256 computed here with the `sha2` API directly, not through camloop's helper.
fn sha256(text: &str) -> String {
    Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The manifest as plain JSON values, parsed independently of camloop's record types.
fn manifest_lines(state: &std::path::Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(state.join(MANIFEST_FILE))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn a_push_puts_the_exact_program_on_the_share_and_records_it() {
    let d = dirs();
    let (mut share, report) = open(&d, 5);
    assert!(report.share_unavailable.is_none());
    let request = next_request(&share, 7);
    let text = request.files[0].text.clone();
    assert!(text.contains("CTABDEF(X,C,1,1)"), "table 1 first: {text}");
    // 360 lines like "C=12.0000 X=20.4158": about 7.7 KB.
    assert!((7_000..9_000).contains(&text.len()), "{}", text.len());

    let pushed = share.push_once(request).unwrap();
    assert_eq!((pushed.version.get(), pushed.table_number), (1, 1));
    assert_eq!(pushed.paths, [d.share.join("CAM_T1.SPF")]);
    // Only the program: no temporary is left on the share.
    assert_eq!(names(&d.share), ["CAM_T1.SPF"]);
    assert_eq!(std::fs::read_to_string(&pushed.paths[0]).unwrap(), text);

    let lines = manifest_lines(&d.state);
    let kinds: Vec<&str> = lines
        .iter()
        .map(|l| l["record"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["version", "delivering", "pushed"]);
    let v = &lines[0];
    assert_eq!(v["version"], 1);
    assert_eq!(v["table_number"], 1);
    assert_eq!(v["files"][0]["name"], "CAM_T1.SPF");
    assert_eq!(v["files"][0]["sha256"], sha256(&text).as_str());
    assert_eq!(v["files"][0]["bytes"], text.len() as u64);
    // The digest's text, as the manifest always held it.
    assert_eq!(
        v["measurement_id"],
        share_support::measurement(7).to_string().as_str()
    );
    assert_eq!(v["learning"]["gain"], 0.5);
    assert_eq!(v["reason"], "learned from measurement m7");
    assert_eq!(v["created_at_unix_ms"], 1_700_000_000_007_u64);
    assert!(v["refused"].is_null() && v["rollback_of"].is_null());
    // The fake clock reads 1 s later at each status.
    assert_eq!(lines[1]["at_unix_ms"], 1_700_000_001_000_u64);
    assert_eq!(lines[2]["at_unix_ms"], 1_700_000_002_000_u64);

    let kept = d
        .state
        .join(VERSIONS_DIR)
        .join("v000001")
        .join("CAM_T1.SPF");
    assert_eq!(std::fs::read_to_string(kept).unwrap(), text);
    assert_eq!(
        share.history().get(ver(1)).unwrap().status,
        VersionStatus::Pushed {
            at: jiff::Timestamp::from_millisecond(1_700_000_002_000).expect("a time"),
            note: None
        }
    );
}

#[test]
fn the_second_push_alternates_the_table_and_keeps_version_1() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    let first = next_request(&share, 1);
    let first_text = first.files[0].text.clone();
    share.push_once(first).unwrap();
    assert_eq!(share.next_table_number(), 2);
    let second = next_request(&share, 2);
    assert!(second.files[0].text.contains("CTABDEF(X,C,2,1)"));
    let pushed = share.push_once(second.clone()).unwrap();
    assert_eq!((pushed.version.get(), pushed.table_number), (2, 2));
    assert_eq!(share.next_table_number(), 1);

    // Both tables are on the share: the previous one may be the one the control runs.
    assert_eq!(names(&d.share), ["CAM_T1.SPF", "CAM_T2.SPF"]);
    assert_eq!(
        std::fs::read_to_string(d.share.join("CAM_T2.SPF")).unwrap(),
        second.files[0].text
    );
    assert_eq!(share.kept_files(ver(1)).unwrap()[0].text, first_text);
    assert!(matches!(
        share.history().get(ver(1)).unwrap().status,
        VersionStatus::Pushed { .. }
    ));

    // The history survives a restart unchanged.
    let before = share.history().clone();
    drop(share);
    let (share, report) = open(&d, 5);
    assert_eq!(share.history(), &before);
    assert_eq!(report.torn_manifest_bytes, 0);
    assert!(report.removed_share_temporaries.is_empty());
}

#[test]
fn a_version_with_two_files_renames_them_in_order_and_verifies_each() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    let mut request = next_request(&share, 3);
    let main = ProgramFile {
        name: "CAMLOOP_GRIND.MPF".into(),
        text: "%_N_CAMLOOP_GRIND_MPF\n;$PATH=/_N_MPF_DIR\nCAM_T1\nM30\n".into(),
    };
    request.files.push(main.clone());
    let pushed = share.push_once(request.clone()).unwrap();
    assert_eq!(
        pushed.paths,
        [
            d.share.join("CAM_T1.SPF"),
            d.share.join("CAMLOOP_GRIND.MPF")
        ]
    );
    for file in &request.files {
        assert_eq!(
            std::fs::read_to_string(d.share.join(&file.name)).unwrap(),
            file.text
        );
    }
    let files = &share.history().get(ver(1)).unwrap().record.files;
    assert_eq!(files[1].name, "CAMLOOP_GRIND.MPF");
    assert_eq!(files[1].sha256, sha256(&main.text));
}

#[test]
fn a_table_that_may_be_in_use_is_refused_recorded_and_never_pushed() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    let first = next_request(&share, 1);
    share.push_once(first.clone()).unwrap();
    let mut same_table = first.clone();
    same_table.files = vec![table_program(1, 99)];
    let err = share.push_once(same_table).unwrap_err();
    assert_eq!(
        err.to_string(),
        "version v2 refused: table 1 may be in use on the control (defined by v1); the next table is 2"
    );
    let mut outside_pair = next_request(&share, 3);
    outside_pair.table_number = 7;
    assert!(matches!(
        share.submit(outside_pair).unwrap(),
        Submitted::Refused { version, ref reason }
            if version.get() == 3 && reason == "table 7 is not the next of the pair (1, 2); the next table is 2"
    ));
    // The share still holds version 1 exactly; refused versions keep no text.
    assert_eq!(
        std::fs::read_to_string(d.share.join("CAM_T1.SPF")).unwrap(),
        first.files[0].text
    );
    assert_eq!(names(&d.state.join(VERSIONS_DIR)), ["v000001"]);
    assert!(matches!(share.kept_files(ver(2)), Err(StateError::NoText(n)) if n.get() == 2));
    assert!(share.history().waiting().is_none());
    // The next good request goes through as v4.
    assert_eq!(
        share
            .push_once(next_request(&share, 4))
            .unwrap()
            .version
            .get(),
        4
    );
}

#[test]
fn bad_file_names_are_refused() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    let cases = [
        (
            "../CAM.SPF",
            "file name \"../CAM.SPF\" is not a plain file name",
        ),
        (
            ".camloop-tmp-x",
            "file name \".camloop-tmp-x\" starts with '.' (reserved for temporaries)",
        ),
        ("", "file name \"\" is empty"),
    ];
    for (name, reason) in cases {
        let mut request = next_request(&share, 1);
        request.files[0].name = name.into();
        match share.push_once(request) {
            Err(PushError::Refused { reason: r, .. }) => assert_eq!(r, reason),
            other => panic!("{name:?}: {other:?}"),
        }
    }
    let mut twice = next_request(&share, 1);
    twice.files.push(twice.files[0].clone());
    assert!(matches!(
        share.push_once(twice),
        Err(PushError::Refused { version, reason }) if version.get() == 4 && reason.ends_with("appears twice")
    ));
    let mut empty = next_request(&share, 1);
    empty.files.clear();
    assert!(matches!(
        share.push_once(empty),
        Err(PushError::Refused { version, reason }) if version.get() == 5 && reason == "no program files"
    ));
    assert!(names(&d.share).is_empty());
}

#[test]
fn rollback_repushes_a_kept_text_as_a_new_version() {
    let d = dirs();
    let (mut share, _) = open(&d, 10);
    let texts: Vec<String> = (1..=3)
        .map(|tag| {
            let request = next_request(&share, tag);
            share.push_once(request.clone()).unwrap();
            request.files[0].text.clone()
        })
        .collect();
    // v1: table 1, v2: table 2, v3: table 1. The next table is 2, so v2 goes back as is.
    let rollback = share
        .rollback_request(
            ver(2),
            jiff::Timestamp::from_millisecond(1_700_000_100_000).unwrap(),
        )
        .unwrap();
    assert_eq!(rollback.reason, "rollback to v2");
    assert_eq!(rollback.rollback_of, Some(ver(2)));
    assert_eq!(rollback.measurement_id, Some(share_support::measurement(2)));
    let pushed = share.push_once(rollback).unwrap();
    assert_eq!((pushed.version.get(), pushed.table_number), (4, 2));
    assert_eq!(
        std::fs::read_to_string(d.share.join("CAM_T2.SPF")).unwrap(),
        texts[1]
    );
    let v4 = &share.history().get(ver(4)).unwrap().record;
    assert_eq!(v4.rollback_of, Some(ver(2)));
    assert_eq!(v4.files[0].sha256, sha256(&texts[1]));

    // v3 defines table 1, which is next now: fine. But v2 again would redefine table 2,
    // which the control may be running since v4: refused, and recorded as refused.
    let again = share
        .rollback_request(
            ver(2),
            jiff::Timestamp::from_millisecond(1_700_000_200_000).unwrap(),
        )
        .unwrap();
    let err = share.push_once(again.clone()).unwrap_err();
    assert!(
        err.to_string()
            .ends_with("table 2 may be in use on the control (defined by v4); the next table is 1"),
        "{err}"
    );
    // Re-rendered for table 1, the rollback goes through.
    let rerendered = PushRequest {
        files: vec![table_program(1, 2)],
        table_number: 1,
        ..again
    };
    let pushed = share.push_once(rerendered).unwrap();
    assert_eq!((pushed.version.get(), pushed.table_number), (6, 1));
    // History is appended, never rewritten: v1..v3 are unchanged and still kept.
    for (i, text) in texts.iter().enumerate() {
        let v = ver(i as u64 + 1);
        assert_eq!(&share.kept_files(v).unwrap()[0].text, text);
        assert!(share.history().get(v).unwrap().record.rollback_of.is_none());
    }
    assert!(matches!(
        share.rollback_request(ver(9), jiff::Timestamp::from_millisecond(0).unwrap()),
        Err(StateError::UnknownVersion(n)) if n.get() == 9
    ));
}

#[test]
fn only_the_newest_kept_versions_keep_their_text() {
    let d = dirs();
    let (mut share, _) = open(&d, 2);
    let mut pruned = Vec::new();
    for tag in 1..=4 {
        pruned.extend(share.push_once(next_request(&share, tag)).unwrap().pruned);
    }
    assert_eq!(pruned, [ver(1), ver(2)]);
    assert_eq!(names(&d.state.join(VERSIONS_DIR)), ["v000003", "v000004"]);
    assert!(matches!(share.kept_files(ver(1)), Err(StateError::NoText(n)) if n.get() == 1));
    assert!(matches!(
        share.rollback_request(ver(2), jiff::Timestamp::from_millisecond(0).unwrap()),
        Err(StateError::NoText(n)) if n.get() == 2
    ));
    // The records stay in the manifest: four versions, all pushed. In memory the share
    // holds only the two with kept text; the pruned ones are settled and forgotten.
    assert_eq!(share.history().next_version().get(), 5);
    let held: Vec<u64> = share
        .history()
        .versions()
        .iter()
        .map(|v| v.record.version.get())
        .collect();
    assert_eq!(held, [3, 4]);
    assert!(share.history().is_forgotten(ver(1)) && share.history().is_forgotten(ver(2)));
    assert_eq!(
        load_manifest(&d.state.join(MANIFEST_FILE))
            .unwrap()
            .history
            .versions()
            .len(),
        4
    );
    let kinds: Vec<serde_json::Value> = manifest_lines(&d.state)
        .into_iter()
        .filter(|l| l["record"] == "pruned")
        .map(|l| l["version"].clone())
        .collect();
    assert_eq!(kinds, [1, 2]);
}

#[test]
fn a_new_start_removes_only_camloop_temporaries_and_orphans() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    share.push_once(next_request(&share, 1)).unwrap();
    drop(share);
    // Leftovers of a killed run, and files that are not ours.
    for (name, text) in [
        (".camloop-tmp-AbC123xyz789", "half a prog"),
        (".camloop-other", "not ours"),
        ("NOTES.TXT", "operator notes"),
        ("camloop-tmp-x", "no leading dot: not ours"),
    ] {
        std::fs::write(d.share.join(name), text).unwrap();
    }
    let versions = d.state.join(VERSIONS_DIR);
    std::fs::create_dir(versions.join(".camloop-tmp-q1w2e3")).unwrap();
    std::fs::create_dir(versions.join("v000002")).unwrap();
    std::fs::write(versions.join("v000002").join("CAM_T2.SPF"), "orphan").unwrap();
    std::fs::write(versions.join("README"), "not ours").unwrap();

    let (_share, report) = open(&d, 5);
    assert_eq!(
        report.removed_share_temporaries,
        [d.share.join(".camloop-tmp-AbC123xyz789")]
    );
    assert_eq!(
        names(&d.share),
        [".camloop-other", "CAM_T1.SPF", "NOTES.TXT", "camloop-tmp-x"]
    );
    let mut removed = report.removed_state_entries.clone();
    removed.sort();
    assert_eq!(
        removed,
        [
            versions.join(".camloop-tmp-q1w2e3"),
            versions.join("v000002")
        ]
    );
    assert_eq!(names(&versions), ["README", "v000001"]);
}

#[test]
fn a_torn_last_manifest_line_is_cut_and_the_history_goes_on() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    share.push_once(next_request(&share, 1)).unwrap();
    drop(share);
    let manifest = d.state.join(MANIFEST_FILE);
    let good = std::fs::read(&manifest).unwrap();
    let torn = b"{\"record\":\"version\",\"version\":2,\"crea";
    std::fs::write(&manifest, [good.as_slice(), torn].concat()).unwrap();

    let (mut share, report) = open(&d, 5);
    assert_eq!(report.torn_manifest_bytes, torn.len() as u64);
    assert_eq!(std::fs::read(&manifest).unwrap(), good);
    assert_eq!(
        share
            .push_once(next_request(&share, 2))
            .unwrap()
            .version
            .get(),
        2
    );
    assert_eq!(manifest_lines(&d.state).len(), 6);
}

#[test]
fn a_recorded_version_waits_across_a_restart_and_is_delivered() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    let request = next_request(&share, 1);
    // Recorded, then the process stops before delivering.
    assert_eq!(
        share.submit(request.clone()).unwrap(),
        Submitted::Accepted { version: ver(1) }
    );
    drop(share);
    assert!(names(&d.share).is_empty());
    let (mut share, _) = open(&d, 5);
    assert_eq!(share.history().waiting().unwrap().record.version.get(), 1);
    let pushed = share.deliver().unwrap().unwrap();
    assert_eq!(pushed.version.get(), 1);
    assert_eq!(
        std::fs::read_to_string(d.share.join("CAM_T1.SPF")).unwrap(),
        request.files[0].text
    );
    assert!(share.deliver().unwrap().is_none());
}

#[test]
fn unusable_settings_are_refused_at_open() {
    let d = dirs();
    let mut config = share_support::config(&d, 0);
    let err = camloop::share::Share::open(
        config.clone(),
        Box::new(camloop::share::RealFs),
        share_support::clock(),
    )
    .unwrap_err();
    assert_eq!(
        err.to_string(),
        "invalid share settings: keep_versions must be at least 1"
    );
    config.keep_versions = 1;
    config.table_pair = (3, 3);
    let err = camloop::share::Share::open(
        config,
        Box::new(camloop::share::RealFs),
        share_support::clock(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("must differ"), "{err}");
}

fn ver(n: u64) -> camloop::core::ids::TableVersion {
    camloop::core::ids::TableVersion::new(n).unwrap()
}
