//! A start after a stop, decided by `FeatureMachine::resume` without I/O, one case of the
//! journal against the share's manifest at a time: a version the share pushed beyond the
//! memory, a version the share holds waiting that the memory does not know (its record in
//! the journal, in the store, or nowhere), a version journalled and never submitted (the
//! share numbering it, or another), a status the share gave and the journal never took,
//! and a start in order, which does nothing. A scripted share answers the machine's
//! effects; each test asserts the memory, the records written and what reached the share.
//! The values are copied, never computed: exact equality is the tolerance.

// The parts and their grinding are the other tests'; a start needs only the recipe.
#[allow(dead_code)]
mod support;

use camloop_core::ids::TableVersion;
use camloop_core::learn::LearningParams;
use camloop_loop::machine::{
    Effect, FROM_THE_MANIFEST, FeatureMachine, Finished, Input, OnShare, ResumeReport, ShareView,
};
use camloop_loop::memory::{LoopMemory, TableLearning, WaitingTable};
use camloop_loop::record::{Kept, Record, SUBMITTED, TableRecord, TableStatus};
use std::collections::BTreeMap;
use support::{Recipe, WHEEL_MM, at};

fn v(n: u64) -> TableVersion {
    TableVersion::new(n).expect("not 0")
}

/// What a table of correction `c_um` everywhere keeps of its learning.
fn learning(c_um: f64, wheel_radius_mm: f64) -> TableLearning {
    TableLearning {
        iteration: c_um as u32,
        params: LearningParams::default(),
        wheel_radius_mm,
        correction_um: vec![c_um; 360],
        timing_correction_deg: 0.01 * c_um,
    }
}

/// Version `n`'s write-ahead record, made from a correction of `c_um`.
fn table(n: u64, c_um: f64) -> Kept {
    Kept::Table(Box::new(TableRecord {
        version: v(n),
        parent: TableVersion::new(n - 1),
        table_number: if n % 2 == 1 { 1 } else { 2 },
        program_text: format!("v{n}"),
        learning: learning(c_um, WHEEL_MM),
        reason: "learned".into(),
        status: TableStatus::Waiting {
            reason: Some(SUBMITTED.into()),
        },
        at: at(n as usize),
        measurement: None,
        rollback_of: None,
    }))
}

/// A memory with version `in_force` on the control, made from a correction of 1 µm.
fn memory(in_force: u64) -> LoopMemory {
    let mut m = LoopMemory::new(WHEEL_MM);
    m.in_force_version = TableVersion::new(in_force);
    m.learning.correction_um = vec![1.0; 360];
    m.learning.iteration = 1;
    m.parts = 5;
    m
}

/// `m` with version `n`, made from a correction of `c_um`, waiting.
fn waiting(mut m: LoopMemory, n: u64, c_um: f64) -> LoopMemory {
    let mut next = m.learning.clone();
    next.correction_um = vec![c_um; 360];
    m.waiting = Some(WaitingTable {
        version: v(n),
        learning: next,
        wheel_radius_mm: WHEEL_MM,
        va_speed_rpm: None,
    });
    m
}

fn share(next: u64, pushed: Option<u64>, versions: &[(u64, OnShare)]) -> ShareView {
    let versions: BTreeMap<_, _> = versions.iter().map(|(n, on)| (v(*n), on.clone())).collect();
    let waiting = versions
        .iter()
        .rev()
        .find(|(_, on)| **on == OnShare::Accepted)
        .map(|(n, _)| *n)
        .filter(|n| Some(*n) > pushed.map(v));
    ShareView {
        next_version: v(next),
        pushed: pushed.map(v),
        waiting,
        versions,
    }
}

/// What a start did: the records it journalled, the versions submitted and delivered, its
/// report, and the machine after it.
struct Started {
    journal: Vec<Record>,
    submitted: Vec<TableVersion>,
    delivered: Vec<TableVersion>,
    report: ResumeReport,
    machine: FeatureMachine,
}

/// Resumes from `records` and carries out the effects: the share takes a submission as
/// the number it would give (`refuse` refuses them all), and delivers what it is asked to.
fn start(records: Vec<Kept>, view: ShareView, found: &[(u64, TableLearning)]) -> Started {
    let recipe = Recipe::new();
    let found = found.iter().map(|(n, l)| (v(*n), l.clone())).collect();
    let fallback = LoopMemory::new(WHEEL_MM);
    let mut next = view.next_version;
    let mut machine =
        FeatureMachine::resume(recipe.config(), records, fallback, view, found, at(99));
    let (mut journal, mut submitted, mut delivered, mut report) = (vec![], vec![], vec![], None);
    while let Some(effect) = machine.poll_effect() {
        let answer = match effect {
            Effect::Journal { ticket, records } => {
                journal.extend(records);
                Some(Input::Journalled(ticket))
            }
            Effect::Submit(record) => {
                let version = next;
                next = next.next();
                submitted.push(record.version);
                Some(Input::Submitted {
                    version,
                    outcome: Ok(()),
                })
            }
            Effect::Deliver { version } => {
                delivered.push(version);
                Some(Input::Delivered {
                    version,
                    at: at(99),
                })
            }
            Effect::Finished(Finished::Resumed(r)) => {
                report = Some(*r);
                None
            }
            Effect::Metric(_) => None,
            other => panic!("a start asks for nothing else: {other:?}"),
        };
        if let Some(answer) = answer {
            machine.handle(answer);
        }
    }
    assert!(!machine.busy(), "the start's work is done");
    Started {
        journal,
        submitted,
        delivered,
        report: report.expect("a start ends with its report"),
        machine,
    }
}

fn learning_of(m: &LoopMemory) -> Kept {
    Kept::Learning(Box::new(m.clone()))
}

fn statuses(journal: &[Record]) -> Vec<(u64, TableStatus)> {
    journal
        .iter()
        .filter_map(|r| match r {
            Record::Status {
                version, status, ..
            } => Some((version.get(), status.clone())),
            _ => None,
        })
        .collect()
}

/// The newest memory written, which a later start resumes from.
fn written_memory(journal: &[Record]) -> Option<LoopMemory> {
    let kept: Vec<Kept> = journal.iter().filter_map(Record::kept).collect();
    LoopMemory::resume(&kept)
}

#[test]
fn a_start_in_order_does_nothing() {
    let m = memory(2);
    let records = vec![table(2, 1.0), learning_of(&m)];
    let view = share(3, Some(2), &[(1, OnShare::Pushed), (2, OnShare::Pushed)]);
    // The journal's status of v2 is still "submitted": the share's word is written.
    let mut records_in_order = records.clone();
    records_in_order.push(Kept::Status {
        version: v(2),
        status: TableStatus::Pushed { note: "x".into() },
    });
    assert!(FeatureMachine::records_wanted(&records_in_order, &m, &view).is_empty());
    let s = start(records_in_order, view, &[]);
    assert_eq!(s.report, ResumeReport::default());
    assert!(s.journal.is_empty() && s.submitted.is_empty() && s.delivered.is_empty());
    assert_eq!(s.machine.memory(), &m);
}

#[test]
fn a_version_pushed_beyond_the_memory_is_in_force_with_its_correction() {
    let m = memory(1);
    let view = share(3, Some(2), &[(1, OnShare::Pushed), (2, OnShare::Pushed)]);
    // Its record in the journal.
    let records = vec![learning_of(&m), table(2, 4.0)];
    assert!(FeatureMachine::records_wanted(&records, &m, &view).is_empty());
    let s = start(records, view.clone(), &[]);
    let after = s.machine.memory();
    assert_eq!(after.in_force_version, Some(v(2)));
    assert_eq!(after.learning.correction_um, vec![4.0; 360]);
    assert_eq!(after.learning.timing_correction_deg, 0.04);
    assert_eq!(after.learning.iteration, 4);
    assert_eq!(after.parts, 5);
    let pushed = TableStatus::Pushed {
        note: FROM_THE_MANIFEST.into(),
    };
    assert_eq!(statuses(&s.journal), vec![(2, pushed)]);
    assert_eq!(written_memory(&s.journal).as_ref(), Some(after));
    assert_eq!(s.report.in_force_from_share, Some((v(2), Some(v(1)), true)));
    assert!(s.submitted.is_empty() && s.delivered.is_empty());

    // Its record only in the store: asked for, and adopted the same.
    let records = vec![learning_of(&m)];
    assert_eq!(
        FeatureMachine::records_wanted(&records, &m, &view),
        vec![v(2)]
    );
    let s = start(
        records.clone(),
        view.clone(),
        &[(2, learning(4.0, WHEEL_MM))],
    );
    assert_eq!(s.machine.memory().learning.correction_um, vec![4.0; 360]);
    assert_eq!(s.machine.memory().in_force_version, Some(v(2)));

    // No record anywhere: in force, learning goes on from the memory's correction.
    let s = start(records, view, &[]);
    assert_eq!(s.machine.memory().in_force_version, Some(v(2)));
    assert_eq!(s.machine.memory().learning, m.learning);
    assert_eq!(
        s.report.in_force_from_share,
        Some((v(2), Some(v(1)), false))
    );
}

#[test]
fn a_version_the_share_holds_waiting_unknown_to_the_memory_waits_for_the_retry() {
    let m = memory(1);
    let view = share(3, Some(1), &[(1, OnShare::Pushed), (2, OnShare::Accepted)]);
    assert_eq!(view.waiting, Some(v(2)));
    let records = vec![learning_of(&m)];
    assert_eq!(
        FeatureMachine::records_wanted(&records, &m, &view),
        vec![v(2)]
    );

    // With the store's record: waiting with the correction it was made from and its wheel.
    let s = start(records.clone(), view.clone(), &[(2, learning(6.0, 249.9))]);
    let w = s.machine.memory().waiting.clone().expect("v2 waits");
    assert_eq!(w.version, v(2));
    assert_eq!(w.learning.correction_um, vec![6.0; 360]);
    assert_eq!(w.wheel_radius_mm, 249.9);
    assert_eq!(w.va_speed_rpm, None);
    assert_eq!(s.machine.memory().in_force_version, Some(v(1)));
    assert_eq!(s.report.adopted_waiting, Some((v(2), true)));
    // Not delivered at start (no record here to finish): the shell's retry ticks it.
    assert!(s.delivered.is_empty() && statuses(&s.journal).is_empty());
    assert_eq!(
        written_memory(&s.journal).as_ref(),
        Some(s.machine.memory())
    );

    // Without a record: waiting as made from the correction in force.
    let s = start(records, view, &[]);
    let w = s.machine.memory().waiting.clone().expect("v2 waits");
    assert_eq!((w.version, &w.learning), (v(2), &m.learning));
    assert_eq!(w.wheel_radius_mm, WHEEL_MM);
    assert_eq!(s.report.adopted_waiting, Some((v(2), false)));
}

#[test]
fn a_version_journalled_and_never_submitted_is_submitted_and_delivered() {
    // The step's write-ahead (its table and the memory with it waiting) was the last write.
    let m = waiting(memory(1), 2, 3.0);
    let records = vec![table(2, 3.0), learning_of(&m)];
    let view = share(2, Some(1), &[(1, OnShare::Pushed)]);
    assert!(FeatureMachine::records_wanted(&records, &m, &view).is_empty());
    let s = start(records, view, &[]);
    assert_eq!(s.submitted, vec![v(2)]);
    assert_eq!(s.delivered, vec![v(2)]);
    assert_eq!(s.report.submitted, vec![v(2)]);
    let after = s.machine.memory();
    assert_eq!(after.in_force_version, Some(v(2)));
    assert_eq!(after.learning.correction_um, vec![3.0; 360]);
    assert!(after.waiting.is_none());
    assert!(matches!(
        statuses(&s.journal).as_slice(),
        [(2, TableStatus::Pushed { .. })]
    ));
    assert_eq!(written_memory(&s.journal).as_ref(), Some(after));
}

#[test]
fn a_journalled_version_the_share_would_number_otherwise_is_refused() {
    // v4 journalled while the share is at v3 (v3's write-ahead was lost with its disk):
    // submitting it would give it another number than its record's.
    let m = waiting(memory(2), 4, 3.0);
    let records = vec![table(4, 3.0), learning_of(&m)];
    let view = share(3, Some(2), &[(2, OnShare::Pushed)]);
    let s = start(records, view, &[]);
    assert!(s.submitted.is_empty() && s.delivered.is_empty());
    let reason = "journalled as v4 but the share is at v3".to_string();
    assert_eq!(s.report.refused, vec![(v(4), reason.clone())]);
    assert_eq!(
        statuses(&s.journal),
        vec![(4, TableStatus::Refused { reason })]
    );
    // It never reaches the control: nothing waits, the table in force stays.
    assert!(s.machine.memory().waiting.is_none());
    assert_eq!(s.machine.memory().in_force_version, Some(v(2)));
    assert_eq!(s.machine.memory().learning, m.learning);
}

#[test]
fn a_status_the_share_gave_and_the_journal_never_took_is_written() {
    // The share refused v2 for good; the stop came before the refusal's record.
    let m = waiting(memory(1), 2, 3.0);
    let records = vec![table(2, 3.0), learning_of(&m)];
    let refused = OnShare::Refused {
        reason: "table number in use".into(),
    };
    let view = share(3, Some(1), &[(1, OnShare::Pushed), (2, refused)]);
    let s = start(records, view, &[]);
    assert_eq!(
        statuses(&s.journal),
        vec![(
            2,
            TableStatus::Refused {
                reason: "table number in use".into()
            }
        )]
    );
    assert_eq!(s.report.settled, vec![(v(2), "refused")]);
    assert!(s.machine.memory().waiting.is_none());
    assert!(
        s.delivered.is_empty(),
        "a refused version is never delivered"
    );
}

#[test]
fn a_share_state_failure_stops_the_start() {
    let m = waiting(memory(1), 2, 3.0);
    let records = vec![table(2, 3.0), learning_of(&m)];
    let view = share(2, Some(1), &[(1, OnShare::Pushed)]);
    let recipe = Recipe::new();
    let fallback = LoopMemory::new(WHEEL_MM);
    let mut machine = FeatureMachine::resume(
        recipe.config(),
        records,
        fallback,
        view,
        BTreeMap::new(),
        at(99),
    );
    assert!(matches!(machine.poll_effect(), Some(Effect::Submit(r)) if r.version == v(2)));
    machine.handle(Input::ShareFailed {
        state: true,
        reason: "state folder read-only".into(),
    });
    match machine.poll_effect() {
        Some(Effect::Finished(Finished::Resumed(r))) => {
            assert_eq!(r.failed.as_deref(), Some("state folder read-only"))
        }
        other => panic!("{other:?}"),
    }
    assert!(machine.poll_effect().is_none() && !machine.busy());
}
