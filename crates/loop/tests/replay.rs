//! Write-ahead ordering as a property of the feature machine, held without I/O: an in-memory
//! executor (a journal that is a list, a share that numbers, accepts and pushes versions, a
//! grinder whose parts carry the correction in force) runs a sequence of parts; for every k
//! it is dropped right after carrying out effect k (the effect happened, the machine never
//! heard), the machine rebuilt from the journal and the share, the part in flight sent again.
//! Every such run must end where the uninterrupted one does: each measurement recorded once,
//! none learned twice, versions 1..n once each and in order, the same memory and tables, bit
//! for bit (the loop is deterministic: there is no tolerance to state).

mod support;

use camloop_core::digest::Sha256;
use camloop_core::ids::{PartId, TableVersion};
use camloop_core::measure::RawMeasurement;
use camloop_core::turn::{correction_sha256, measurement_sha256};
use camloop_loop::machine::{
    Effect, FeatureMachine, Finished, Gauged, Input, OnShare, Program, ShareView,
};
use camloop_loop::memory::LoopMemory;
use camloop_loop::record::{Kept, Record, TableRecord, TableStatus};
use support::{Recipe, WHEEL_MM, at, grind, nominal_mm};

const PARTS: usize = 14;
/// Parts (by index) while the share cannot take a table: an outage in the middle.
const OUTAGE: std::ops::Range<usize> = 6..9;
/// A part whose gauge lost a revolution's samples: rejected by the checks.
const TORN: usize = 3;
/// A part the source sends twice (a drop file copied): the second is a repeat.
const REPEATED: usize = 10;

/// The share: versions numbered 1, 2, … as accepted; a delivery pushes the newest accepted.
#[derive(Debug, Clone, Default, PartialEq)]
struct Share {
    accepted: Vec<TableRecord>,
    pushed: Option<TableVersion>,
    /// Every version pushed (one accepted during an outage and superseded before it ended
    /// never is).
    delivered: Vec<TableVersion>,
    available: bool,
}

impl Share {
    fn next_version(&self) -> TableVersion {
        TableVersion::new(self.accepted.len() as u64 + 1).expect("never 0")
    }

    fn view(&self) -> ShareView {
        let versions = self
            .accepted
            .iter()
            .map(|t| {
                let on = if self.delivered.contains(&t.version) {
                    OnShare::Pushed
                } else {
                    OnShare::Accepted
                };
                (t.version, on)
            })
            .collect();
        ShareView {
            next_version: self.next_version(),
            pushed: self.pushed,
            waiting: self.waiting(),
            versions,
        }
    }

    /// The correction of the table on the control (none before the first).
    fn correction_um(&self) -> Vec<f64> {
        self.pushed
            .map(|v| {
                self.accepted[v.get() as usize - 1]
                    .learning
                    .correction_um
                    .clone()
            })
            .unwrap_or_else(|| vec![0.0; 360])
    }

    /// A version accepted and not pushed.
    fn waiting(&self) -> Option<TableVersion> {
        let newest = TableVersion::new(self.accepted.len() as u64)?;
        (self.pushed != Some(newest)).then_some(newest)
    }
}

/// The largest |lift error| of a part's first revolution, µm.
fn worst_error_um(raw: &RawMeasurement) -> f64 {
    raw.samples
        .iter()
        .filter(|s| s.revolution == 0)
        .map(|s| ((s.lift_mm - nominal_mm(s.angle_index)) * 1000.0).abs())
        .fold(0.0, f64::max)
}

/// What a run leaves: the durable journal and the share.
#[derive(Debug, Default)]
struct World {
    journal: Vec<Record>,
    share: Share,
    /// Each part as first ground (a part sent again is the same reading).
    parts: Vec<RawMeasurement>,
}

/// The executor, dropped after it carried out effect number `crash_after` (counted over the
/// whole run, from 1).
struct Executor<'r> {
    recipe: &'r Recipe,
    machine: FeatureMachine,
    effects_done: usize,
    crash_after: Option<usize>,
}

/// The executor stopped (the process died) after carrying out an effect.
#[derive(Debug)]
struct Crashed;

impl Executor<'_> {
    /// Carries out the machine's effects until it has none, answering each.
    fn run(&mut self, world: &mut World, index: usize) -> Result<Vec<Finished>, Crashed> {
        let mut finished = Vec::new();
        while let Some(effect) = self.machine.poll_effect() {
            let answer = carry_out(effect, world, index, &mut finished);
            self.effects_done += 1;
            if Some(self.effects_done) == self.crash_after {
                return Err(Crashed);
            }
            if let Some(answer) = answer {
                self.machine.handle(answer);
            }
        }
        Ok(finished)
    }

    /// The shell's retry: a tick, on which the machine delivers what waits for the share.
    fn retry(&mut self, world: &mut World, index: usize) -> Result<(), Crashed> {
        self.machine.handle(Input::Tick);
        self.run(world, index).map(|_| ())
    }

    /// Part `index`, ground now unless it was before (then the same reading again).
    fn part(&mut self, world: &mut World, index: usize) -> Result<Vec<Finished>, Crashed> {
        if world.parts.len() == index {
            let raw = grind(index, &world.share.correction_um(), index == TORN);
            world.parts.push(raw);
        }
        let raw = world.parts[index].clone();
        let setup = self.recipe.setup();
        self.machine.handle(Input::Gauged(Box::new(Gauged {
            setup,
            raw: &raw,
            sha256: measurement_sha256(&raw),
            part: PartId::new(&raw.header.part).ok(),
            ground_with: None,
            on_reserve: false,
            at: at(index),
        })));
        self.run(world, index)
    }
}

/// One effect against the world; the machine's answer, if it asked for one.
fn carry_out(
    effect: Effect,
    world: &mut World,
    index: usize,
    finished: &mut Vec<Finished>,
) -> Option<Input<'static>> {
    let share = &mut world.share;
    match effect {
        Effect::Journal { ticket, records } => {
            world.journal.extend(records);
            Some(Input::Journalled(ticket))
        }
        Effect::Render(order) => {
            let version = share.next_version();
            let (text, table_number) = match order.program {
                Program::Table { table, .. } => (
                    format!(
                        "v{version} {} points, correction {}, parent {:?}",
                        table.points.len(),
                        correction_sha256(&order.next.correction_um),
                        order.parent
                    ),
                    if version.get() % 2 == 1 { 1 } else { 2 },
                ),
                Program::Text { text, table_number } => (text, table_number),
            };
            Some(Input::Rendered {
                version,
                table_number,
                text,
                va_speed_rpm: None,
            })
        }
        Effect::Submit(record) => {
            // Write-ahead: the share never hears of a version the journal does not hold,
            // nor of one learned from a measurement the journal does not hold.
            let journalled = |r: &Record| matches!(r, Record::Table(t) if **t == *record);
            assert!(
                world.journal.iter().any(journalled),
                "v{} submitted before its record was journalled",
                record.version
            );
            if let Some(sha) = record.measurement {
                let measured =
                    |r: &Record| matches!(r, Record::Measurement { sha256, .. } if *sha256 == sha);
                assert!(
                    world.journal.iter().any(measured),
                    "v{} submitted before its measurement was journalled",
                    record.version
                );
            }
            let version = record.version;
            let outcome = if version == share.next_version() {
                share.accepted.push(*record);
                Ok(())
            } else {
                Err(format!(
                    "journalled as v{version} but the share is at v{}",
                    share.next_version()
                ))
            };
            Some(Input::Submitted { version, outcome })
        }
        Effect::Deliver { version } => {
            assert_eq!(
                share.waiting(),
                Some(version),
                "only a version accepted and not pushed is delivered"
            );
            Some(if share.available {
                share.pushed = Some(version);
                share.delivered.push(version);
                Input::Delivered {
                    version,
                    at: at(index),
                }
            } else {
                Input::ShareUnavailable {
                    version,
                    reason: "share folder not mounted".into(),
                    at: at(index),
                }
            })
        }
        Effect::Finished(f) => {
            finished.push(f);
            None
        }
        Effect::KeepReject { .. } | Effect::Alarm(_) | Effect::Metric(_) => None,
    }
}

/// The sequence of inputs from part `from`: before each part the shell's retry, then the
/// part (sent twice for [`REPEATED`]).
fn sequence(exec: &mut Executor<'_>, world: &mut World, from: usize) -> Result<(), Crashed> {
    for index in from..PARTS {
        world.share.available = !OUTAGE.contains(&index);
        exec.retry(world, index)?;
        let done = exec.part(world, index)?;
        let expected = match index {
            TORN => matches!(done.last(), Some(Finished::Rejected { .. })),
            _ => matches!(
                done.last(),
                Some(Finished::Recorded(_) | Finished::Repeated)
            ),
        };
        assert!(expected, "part {index}: {done:?}");
        if index == REPEATED {
            let again = exec.part(world, index)?;
            assert!(
                matches!(again.last(), Some(Finished::Repeated)),
                "{again:?}"
            );
        }
    }
    Ok(())
}

/// A full run with the executor dropped after effect `crash_after` (and the machine rebuilt
/// from the journal and the share, the part in flight sent again). Returns the world, the
/// final memory, and whether the stop happened.
fn run(recipe: &Recipe, crash_after: Option<usize>) -> (World, LoopMemory, bool) {
    let mut world = World {
        share: Share {
            available: true,
            ..Share::default()
        },
        ..World::default()
    };
    let mut exec = Executor {
        recipe,
        machine: FeatureMachine::new(recipe.config(), LoopMemory::new(WHEEL_MM)),
        effects_done: 0,
        crash_after,
    };
    if sequence(&mut exec, &mut world, 0).is_ok() {
        return (world, exec.machine.memory().clone(), false);
    }
    // The process died: what is left is the journal and the share. The part in flight is
    // the newest one ground; its source was never told it was done, so it sends it again.
    let in_flight = world.parts.len().saturating_sub(1);
    world.share.available = !OUTAGE.contains(&in_flight);
    let machine = FeatureMachine::resume(
        recipe.config(),
        kept(&world.journal),
        LoopMemory::new(WHEEL_MM),
        world.share.view(),
        Default::default(),
        at(in_flight),
    );
    let mut exec = Executor {
        recipe,
        machine,
        effects_done: 0,
        crash_after: None,
    };
    let rest = exec.run(&mut world, in_flight);
    rest.and_then(|_| sequence(&mut exec, &mut world, in_flight))
        .expect("one stop a run");
    (world, exec.machine.memory().clone(), true)
}

fn kept(journal: &[Record]) -> Vec<Kept> {
    journal.iter().filter_map(Record::kept).collect()
}

fn measurements(journal: &[Record]) -> Vec<Sha256> {
    journal
        .iter()
        .filter_map(|r| match r {
            Record::Measurement { sha256, .. } => Some(*sha256),
            _ => None,
        })
        .collect()
}

fn tables(journal: &[Record]) -> Vec<&TableRecord> {
    journal
        .iter()
        .filter_map(|r| match r {
            Record::Table(t) => Some(t.as_ref()),
            _ => None,
        })
        .collect()
}

#[test]
fn a_stop_after_any_effect_loses_nothing_and_learns_nothing_twice() {
    let recipe = Recipe::new();
    let (clean, clean_memory, crashed) = run(&recipe, None);
    assert!(!crashed);
    // The uninterrupted run is worth comparing with: it learned, rejected the torn part,
    // recognised the repeat, kept a table waiting through the outage and pushed it after.
    let recorded = measurements(&clean.journal);
    assert_eq!(
        recorded.len(),
        PARTS - 1,
        "every part but the torn one, once"
    );
    assert_eq!(clean_memory.parts, (PARTS - 1) as u64);
    let versions = clean.share.accepted.len();
    assert!(versions >= 8, "tables made: {versions}");
    assert_eq!(clean.share.pushed, TableVersion::new(versions as u64));
    assert!(clean_memory.waiting.is_none());
    assert_eq!(clean_memory.in_force_version, clean.share.pushed);
    let waited = clean.journal.iter().any(|r| {
        matches!(
            r,
            Record::Status {
                status: TableStatus::Waiting { .. },
                ..
            }
        )
    });
    assert!(waited, "the outage kept a table waiting");
    let (first, last) = (
        worst_error_um(&clean.parts[0]),
        worst_error_um(&clean.parts[PARTS - 1]),
    );
    assert!(
        last < 0.5 * first,
        "the loop learned: {first:.2} µm → {last:.2} µm"
    );

    let mut k = 1;
    loop {
        let (world, memory, crashed) = run(&recipe, Some(k));
        if !crashed {
            // Past the run's last effect: every stop point was tried.
            assert!(k > 50, "only {k} effects in a run");
            break;
        }
        // No measurement lost, none recorded twice.
        assert_eq!(
            measurements(&world.journal),
            recorded,
            "stop after effect {k}: measurements journalled"
        );
        // None learned twice: one table per learning step at most.
        let t = tables(&world.journal);
        let mut from: Vec<_> = t.iter().filter_map(|t| t.measurement).collect();
        let steps = from.len();
        from.sort_by_key(|s| s.to_string());
        from.dedup();
        assert_eq!(
            from.len(),
            steps,
            "stop after effect {k}: a measurement learned twice"
        );
        // Versions 1..n, each once, in order, in the journal and on the share.
        let numbers: Vec<u64> = t.iter().map(|t| t.version.get()).collect();
        assert_eq!(
            numbers,
            (1..=versions as u64).collect::<Vec<_>>(),
            "stop after effect {k}: versions journalled"
        );
        assert_eq!(world.share, clean.share, "stop after effect {k}: the share");
        // The same loop, bit for bit.
        assert_eq!(memory, clean_memory, "stop after effect {k}: the memory");
        assert_eq!(
            LoopMemory::resume(&kept(&world.journal)).as_ref(),
            Some(&memory),
            "stop after effect {k}: the journal's newest memory is the machine's"
        );
        k += 1;
    }
}
