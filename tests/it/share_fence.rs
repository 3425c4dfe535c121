//! Fencing on the real file system: two owners of one machine's state folder, as after a
//! takeover while the old owner was paused (cut off from the database, stopped by the
//! kernel). Once the new owner has claimed a higher epoch, the old one can neither record
//! nor deliver a version, and every version in the manifest carries the epoch that wrote it.

use crate::share_support;

use camloop::cluster::Epoch;
use camloop::share::{Fence, PushError, StateError, Submitted, load_manifest};
use share_support::{dirs, names, next_request, open};

/// Long enough for any write here.
const WAIT: std::time::Duration = std::time::Duration::from_secs(10);

fn is_fenced(e: &StateError, mine: u64, current: u64) -> bool {
    matches!(e, StateError::Fenced { mine: m, current: c, .. } if (m.0, c.0) == (mine, current))
}

#[test]
fn an_owner_fenced_out_can_neither_record_nor_deliver() {
    let d = dirs();
    let machine = d.root.path().join("machine");
    let (mut old, _) = open(&d, 5);
    old.set_fence(Fence::claim(&machine, Epoch(1), "a", WAIT).unwrap());
    let v1 = old.push_once(next_request(&old, 1)).unwrap();
    assert_eq!(v1.version.get(), 1);
    // v2 is recorded by the old owner, not yet delivered, when the new owner claims.
    let Submitted::Accepted { version } = old.submit(next_request(&old, 2)).unwrap() else {
        panic!("v2 not accepted")
    };
    assert_eq!(version.get(), 2);

    let new_fence = Fence::claim(&machine, Epoch(2), "b", WAIT).unwrap();
    match old.deliver() {
        Err(PushError::State(e)) => assert!(is_fenced(&e, 1, 2), "{e}"),
        other => panic!("the old owner delivered after the claim: {other:?}"),
    }
    match old.submit(next_request(&old, 3)) {
        Err(e) => assert!(is_fenced(&e, 1, 2), "{e}"),
        Ok(s) => panic!("the old owner recorded a version after the claim: {s:?}"),
    }
    // The share still holds only v1's program.
    assert_eq!(names(&d.share), ["CAM_T1.SPF"]);

    // The new owner opens the state folder, delivers the waiting v2 and goes on.
    let (mut new, _) = open(&d, 5);
    new.set_fence(new_fence);
    let v2 = new.deliver().unwrap().expect("v2 waiting");
    assert_eq!(v2.version.get(), 2);
    let v3 = new.push_once(next_request(&new, 4)).unwrap();
    assert_eq!(v3.version.get(), 3);

    let history = load_manifest(&d.state.join("manifest.jsonl"))
        .unwrap()
        .history;
    let epochs: Vec<(u64, Option<u64>)> = history
        .versions()
        .iter()
        .map(|v| (v.record.version.get(), v.record.epoch.map(|e| e.0)))
        .collect();
    // v2 was recorded under epoch 1 and delivered under 2: a version keeps the epoch of the
    // owner that recorded it, and versions never go back to an older epoch.
    assert_eq!(epochs, [(1, Some(1)), (2, Some(1)), (3, Some(2))]);
}

#[test]
fn without_a_fence_a_share_records_no_epoch() {
    let d = dirs();
    let (mut share, _) = open(&d, 5);
    share.push_once(next_request(&share, 1)).unwrap();
    let history = load_manifest(&d.state.join("manifest.jsonl"))
        .unwrap()
        .history;
    assert_eq!(history.versions()[0].record.epoch, None);
    let text = std::fs::read_to_string(d.state.join("manifest.jsonl")).unwrap();
    assert!(!text.contains("epoch"), "{text}");
}
