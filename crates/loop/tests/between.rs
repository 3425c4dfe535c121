//! What happens between parts, decided by the machine without I/O: a dressing moves the
//! correction and delivers the table made again for the dressed wheel, a part not gauged
//! moves the table on by the learned drift (or is only noted), and freezing is the
//! machine's write.

#[allow(dead_code)]
mod support;

use camloop_core::compensate::Feature;
use camloop_core::geometry::{CamGeometry, Follower};
use camloop_core::ids::{PartId, TableVersion};
use camloop_loop::dressing::{CorrectionMove, Dressing};
use camloop_loop::machine::{
    Dressed, DressingDone, Effect, FeatureMachine, Finished, Input, NotGaugedDone, TableDone,
};
use camloop_loop::memory::LoopMemory;
use camloop_loop::record::{Record, TableStatus};
use support::{Recipe, WHEEL_MM, at};

/// What the machine asked and came to, with every answer the shell would give when all
/// goes well (the share numbers versions from `next_version`).
#[derive(Default)]
struct Run {
    finished: Vec<Finished>,
    journal: Vec<Vec<Record>>,
    rendered: Vec<camloop_loop::machine::RenderOrder>,
}

fn drive(machine: &mut FeatureMachine, next_version: u64) -> Run {
    let mut run = Run::default();
    while let Some(effect) = machine.poll_effect() {
        let answer = match effect {
            Effect::Render(order) => {
                run.rendered.push(*order);
                Some(Input::Rendered {
                    version: TableVersion::new(next_version).unwrap(),
                    table_number: 1,
                    text: "table".into(),
                    va_speed_rpm: None,
                })
            }
            Effect::Journal { ticket, records } => {
                run.journal.push(records);
                Some(Input::Journalled(ticket))
            }
            Effect::Submit(record) => Some(Input::Submitted {
                version: record.version,
                outcome: Ok(()),
            }),
            Effect::Deliver { version } => Some(Input::Delivered { version, at: at(1) }),
            Effect::Finished(f) => {
                run.finished.push(f);
                None
            }
            Effect::KeepReject { .. } | Effect::Alarm(_) | Effect::Metric(_) => None,
        };
        if let Some(answer) = answer {
            machine.handle(answer);
        }
    }
    run
}

fn table_done(run: &Run) -> &TableDone {
    run.finished
        .iter()
        .find_map(|f| match f {
            Finished::Table(Ok(done)) => Some(done),
            _ => None,
        })
        .expect("a table delivered")
}

/// The dresser took 12 µm off a wheel the control now believes 10 µm smaller: the size
/// step is 12 − 10 = 2 µm (what the infeed removed beyond the radius the control moved),
/// so the correction moves by −2 µm everywhere, and the table made again for the dressed
/// wheel reaches the control with that correction and radius.
#[test]
fn a_dressing_moves_the_correction_and_delivers_the_table_for_the_new_wheel() {
    let recipe = Recipe::new();
    let mut machine = FeatureMachine::new(recipe.config(), LoopMemory::new(WHEEL_MM));
    let new_radius_mm = WHEEL_MM - 0.010;
    let mut setup = recipe.setup();
    setup.lobe.feature = Feature::Cam(CamGeometry {
        base_radius_mm: 20.0,
        follower: Follower::Flat,
        wheel_radius_mm: new_radius_mm,
    });
    machine.handle(Input::Dressed(Box::new(Dressed {
        dressing: Dressing {
            old_radius_mm: WHEEL_MM,
            new_radius_mm,
            infeed_um: Some(12.0),
            share_um: 0.0,
        },
        lobe: &setup.lobe,
        at: at(0),
    })));
    let run = drive(&mut machine, 1);
    let Some(Finished::Dressed(DressingDone {
        moved: CorrectionMove::SizeStep { step_um, .. },
        no_table: None,
    })) = run.finished.first()
    else {
        panic!("the dressing's move comes first: {:?}", run.finished);
    };
    assert!((step_um - 2.0).abs() < 1e-9, "size step {step_um} µm");
    let order = &run.rendered[0];
    assert_eq!(order.reason, format!("wheel dressed to {new_radius_mm} mm"));
    assert_eq!(order.learning.wheel_radius_mm, new_radius_mm);
    // The correction is kept to 0.01 µm steps (quantised), so −2 µm exactly.
    assert!(order.next.correction_um.iter().all(|u| *u == -2.0));
    let done = table_done(&run);
    assert_eq!(done.version, TableVersion::FIRST);
    assert!(matches!(done.status, TableStatus::Pushed { .. }));
    let memory = machine.memory();
    assert_eq!(memory.in_force_version, Some(TableVersion::FIRST));
    assert_eq!(memory.wheel_radius_mm, new_radius_mm);
    assert!(memory.learning.correction_um.iter().all(|u| *u == -2.0));
}

/// A part not gauged with 0.5 µm of learned drift per part: the table moves on by it (the
/// correction by −0.5 µm), and the part is remembered as ground. With no drift, or a table
/// waiting for the share, the part is only noted, in one write of the memory.
#[test]
fn a_part_not_gauged_moves_the_table_by_the_drift_or_is_only_noted() {
    let recipe = Recipe::new();
    let setup = recipe.setup();
    let part = PartId::new("S-7").unwrap();

    let mut drifting = LoopMemory::new(WHEEL_MM);
    drifting.learning.size_drift_um_per_part = 0.5;
    let mut machine = FeatureMachine::new(recipe.config(), drifting);
    machine.handle(Input::NotGauged {
        part: Some(part.clone()),
        lobe: &setup.lobe,
        at: at(0),
    });
    let run = drive(&mut machine, 1);
    assert!(matches!(
        run.finished.first(),
        Some(Finished::NotGauged(NotGaugedDone::Table))
    ));
    assert!(
        run.rendered[0]
            .reason
            .contains("part S-7 ground, not gauged")
    );
    assert_eq!(table_done(&run).version, TableVersion::FIRST);
    let memory = machine.memory();
    assert!(memory.learning.correction_um.iter().all(|u| *u == -0.5));
    assert_eq!(memory.last_part.as_ref(), Some(&part));

    for waiting in [false, true] {
        let mut memory = LoopMemory::new(WHEEL_MM);
        if waiting {
            memory.learning.size_drift_um_per_part = 0.5;
            memory.waiting = Some(camloop_loop::memory::WaitingTable {
                version: TableVersion::FIRST,
                learning: memory.learning.clone(),
                wheel_radius_mm: WHEEL_MM,
                va_speed_rpm: None,
            });
        }
        let mut machine = FeatureMachine::new(recipe.config(), memory);
        machine.handle(Input::NotGauged {
            part: Some(part.clone()),
            lobe: &setup.lobe,
            at: at(0),
        });
        let run = drive(&mut machine, 2);
        assert!(
            matches!(
                run.finished.as_slice(),
                [Finished::NotGauged(NotGaugedDone::Noted)]
            ),
            "waiting {waiting}: {:?}",
            run.finished
        );
        assert!(run.rendered.is_empty(), "no table when waiting {waiting}");
        let [records] = run.journal.as_slice() else {
            panic!("one write");
        };
        let [Record::Learning { memory, .. }] = records.as_slice() else {
            panic!("the memory is written: {records:?}");
        };
        assert_eq!(memory.last_part.as_ref(), Some(&part));
        assert!(memory.learning.correction_um.iter().all(|u| *u == 0.0));
    }
}

/// Freezing keeps the reason and writes the memory; unfreezing forgets the recent errors
/// (the revert guard then judges only parts ground after the decision) and says the reason
/// before.
#[test]
fn freezing_is_the_machines_write() {
    let recipe = Recipe::new();
    let mut memory = LoopMemory::new(WHEEL_MM);
    memory.learning.recent_max_error_um = vec![3.0, 4.0];
    let mut machine = FeatureMachine::new(recipe.config(), memory);
    machine.handle(Input::Freeze {
        frozen: Some("trial".into()),
        at: at(0),
    });
    let run = drive(&mut machine, 1);
    assert!(matches!(
        run.finished.as_slice(),
        [Finished::Frozen { before: None }]
    ));
    let [Record::Learning { memory, .. }] = run.journal[0].as_slice() else {
        panic!("the memory is written");
    };
    assert_eq!(memory.learning.frozen.as_deref(), Some("trial"));
    assert_eq!(memory.learning.recent_max_error_um, vec![3.0, 4.0]);

    machine.handle(Input::Freeze {
        frozen: None,
        at: at(1),
    });
    let run = drive(&mut machine, 1);
    let [Finished::Frozen { before }] = run.finished.as_slice() else {
        panic!("{:?}", run.finished);
    };
    assert_eq!(before.as_deref(), Some("trial"));
    assert!(machine.memory().learning.frozen.is_none());
    assert!(machine.memory().learning.recent_max_error_um.is_empty());
}

/// The retry is the machine's: a tick delivers the version waiting for the share (nothing
/// when none waits); while the share is down it still waits, and once delivered its
/// correction is the one in force.
#[test]
fn a_tick_delivers_the_waiting_version() {
    let recipe = Recipe::new();
    let mut machine = FeatureMachine::new(recipe.config(), LoopMemory::new(WHEEL_MM));
    machine.handle(Input::Tick);
    assert!(machine.poll_effect().is_none(), "nothing waits");

    let mut memory = LoopMemory::new(WHEEL_MM);
    let mut learned = memory.learning.clone();
    learned.correction_um = vec![1.5; 360];
    memory.waiting = Some(camloop_loop::memory::WaitingTable {
        version: TableVersion::FIRST,
        learning: learned,
        wheel_radius_mm: WHEEL_MM,
        va_speed_rpm: None,
    });
    let mut machine = FeatureMachine::new(recipe.config(), memory);
    for share_up in [false, true] {
        machine.handle(Input::Tick);
        let Some(Effect::Deliver { version }) = machine.poll_effect() else {
            panic!("the waiting version is delivered");
        };
        assert_eq!(version, TableVersion::FIRST);
        machine.handle(if share_up {
            Input::Delivered { version, at: at(1) }
        } else {
            Input::ShareUnavailable {
                version,
                reason: "share folder not mounted".into(),
                at: at(1),
            }
        });
        let run = drive(&mut machine, 2);
        if share_up {
            assert!(matches!(
                run.finished.as_slice(),
                [Finished::ShareBack { version }] if *version == TableVersion::FIRST
            ));
        } else {
            let [Finished::StillWaiting { reason, .. }] = run.finished.as_slice() else {
                panic!("{:?}", run.finished);
            };
            assert_eq!(reason, "share folder not mounted");
            assert!(machine.memory().waiting.is_some());
        }
    }
    let memory = machine.memory();
    assert_eq!(memory.in_force_version, Some(TableVersion::FIRST));
    assert!(memory.waiting.is_none());
    assert!(memory.learning.correction_um.iter().all(|u| *u == 1.5));
}
