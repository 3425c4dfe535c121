//! The write-ahead order effect by effect, without I/O: what a part's step asks for, and
//! what it does not ask for until the write before it is durable.

mod support;

use camloop_core::ids::{PartId, TableVersion};
use camloop_core::measure::RawMeasurement;
use camloop_core::turn::measurement_sha256;
use camloop_loop::machine::{Effect, FeatureMachine, Finished, Gauged, Input};
use camloop_loop::memory::LoopMemory;
use camloop_loop::record::Record;
use support::{Recipe, WHEEL_MM, at, grind};

/// The order itself, effect by effect: the table is rendered, then one journal write holds
/// the measurement, the table's record and the memory with it waiting; nothing is submitted
/// until that write is reported durable, and a write that fails leaves nothing learned.
#[test]
fn nothing_reaches_the_share_before_its_write_is_durable() {
    let recipe = Recipe::new();
    let mut machine = FeatureMachine::new(recipe.config(), LoopMemory::new(WHEEL_MM));
    let raw = grind(0, &[0.0; 360], false);
    fn gauged<'a>(recipe: &'a Recipe, raw: &'a RawMeasurement) -> Gauged<'a> {
        Gauged {
            setup: recipe.setup(),
            raw,
            sha256: measurement_sha256(raw),
            part: PartId::new(&raw.header.part).ok(),
            ground_with: None,
            on_reserve: false,
            at: at(0),
        }
    }
    machine.handle(Input::Gauged(Box::new(gauged(&recipe, &raw))));
    assert!(matches!(machine.poll_effect(), Some(Effect::Render(_))));
    assert!(
        machine.poll_effect().is_none(),
        "nothing before the render's answer"
    );
    machine.handle(Input::Rendered {
        version: TableVersion::FIRST,
        table_number: 1,
        text: "T1".into(),
        va_speed_rpm: None,
    });
    let Some(Effect::Journal { ticket, records }) = machine.poll_effect() else {
        panic!("the write-ahead comes next");
    };
    let kinds: Vec<&str> = records
        .iter()
        .map(|r| match r {
            Record::Measurement { .. } => "measurement",
            Record::Table(_) => "table",
            Record::Learning { memory, .. } => {
                assert_eq!(
                    memory.waiting.as_ref().map(|w| w.version),
                    Some(TableVersion::FIRST)
                );
                assert_eq!(memory.parts, 1);
                "learning"
            }
            _ => "other",
        })
        .collect();
    assert_eq!(kinds, ["measurement", "table", "learning"]);
    assert!(
        machine.poll_effect().is_none(),
        "no submit before the write is durable"
    );
    assert_eq!(
        machine.memory().parts,
        0,
        "nothing is the memory's before it is durable"
    );
    machine.handle(Input::JournalFailed {
        ticket,
        fenced_out: false,
        reason: "disk full".into(),
    });
    let mut rest = Vec::new();
    while let Some(e) = machine.poll_effect() {
        rest.push(e);
    }
    assert!(
        !rest
            .iter()
            .any(|e| matches!(e, Effect::Submit(_) | Effect::Deliver { .. })),
        "{rest:?}"
    );
    assert!(matches!(
        rest.last(),
        Some(Effect::Finished(Finished::NotRecorded))
    ));
    assert_eq!(
        machine.memory(),
        &LoopMemory::new(WHEEL_MM),
        "nothing learned"
    );
    // Sent again once the journal can be written, it is a new measurement, not a repeat.
    machine.handle(Input::Gauged(Box::new(gauged(&recipe, &raw))));
    assert!(matches!(machine.poll_effect(), Some(Effect::Render(_))));
}
