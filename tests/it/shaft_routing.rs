//! Each lobe's measurement reaches its own loop and no other: two lobes of the demo camshaft
//! with the same lift at different phases on the shaft (IN1 at 0°, IN2 at 270°), so their
//! shapes alone cannot tell them apart. Swapped labels are refused (the timing is 90° off,
//! far beyond any timing correction) or, when the control reports which table ground the
//! part, rejected before any loop sees them. Never is one lobe learned from the other's part.

use crate::machine_support::{nominal_measurement, start_machine};
use camloop::core::measure::RawMeasurement;
use camloop::recipe::{FeatureSetup, Recipe};
use camloop::service::machine::{GroundWith, Ingested, MachineLoop, SourceEvent};
use camloop::service::metrics::Metrics;
use camloop::sim::PartLabels;
use std::path::Path;
use std::sync::Arc;

fn setups() -> Vec<FeatureSetup> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
    let recipe = Recipe::load(&path).unwrap();
    ["IN1", "IN2"]
        .iter()
        .map(|n| recipe.feature_setup(&path, n).unwrap())
        .collect()
}

/// A measurement of `setup` ground from its nominal table, read in the shaft's frame (the
/// gauge's index 0 at the shaft datum, the lobe at its phase), labelled `lobe`.
fn measurement(setup: &FeatureSetup, part: &str, lobe: &str, seed: u64) -> RawMeasurement {
    let labels = PartLabels {
        machine: "M2".into(),
        part: part.into(),
        lobe: lobe.into(),
    };
    let mut raw = nominal_measurement(setup, labels, seed);
    let shift = (setup.phase_deg / 360.0 * 360.0).round() as u32;
    for s in &mut raw.samples {
        s.angle_index = (s.angle_index + shift) % 360;
    }
    raw
}

async fn machine(dir: &Path) -> MachineLoop {
    start_machine(dir, "M2", setups(), Arc::new(Metrics::default())).await
}

async fn feed(
    m: &mut MachineLoop,
    raw: RawMeasurement,
    ground_with: Option<GroundWith>,
) -> Ingested {
    let (done, answer) = tokio::sync::oneshot::channel();
    m.handle(SourceEvent::Measurement {
        raw,
        ground_with,
        done: Some(done),
    })
    .await;
    answer.await.unwrap()
}

/// (iteration, correction, timing correction) of each lobe's loop.
fn states(m: &MachineLoop) -> Vec<(u32, Vec<f64>, f64)> {
    m.features()
        .iter()
        .map(|f| {
            let l = &f.memory().learning;
            (
                l.iteration,
                l.correction_um.clone(),
                l.timing_correction_deg,
            )
        })
        .collect()
}

#[tokio::test]
async fn swapped_lobes_are_refused_or_rejected_never_learned_crosswise() {
    let dir = tempfile::tempdir().unwrap();
    let mut m = machine(dir.path()).await;
    let s = setups();
    // Each lobe's own part, labelled by name and by position: both learned.
    assert_eq!(
        feed(&mut m, measurement(&s[0], "1", "IN1", 1), None).await,
        Ingested::Recorded
    );
    assert_eq!(
        feed(&mut m, measurement(&s[1], "1", "2", 2), None).await,
        Ingested::Recorded
    );
    let learned = states(&m);
    assert_eq!((learned[0].0, learned[1].0), (1, 1));
    // The lag shows in both as about +0.08° of timing, corrected in each one's C offset.
    for (_, _, timing) in &learned {
        assert!((-0.08..-0.05).contains(timing), "{timing}");
    }

    // Swapped labels, no report from the control: each part looks 90° off its lobe's
    // timing, beyond any timing correction. Refused: the measurement is kept, nothing learned.
    let a = measurement(&s[0], "2", "IN2", 3);
    let b = measurement(&s[1], "2", "IN1", 4);
    feed(&mut m, a, None).await;
    feed(&mut m, b, None).await;
    assert_eq!(states(&m), learned, "a swapped part was learned from");

    // Swapped labels with the control's report of the table each part was ground with:
    // rejected before any loop.
    let report = |f: &str| {
        Some(GroundWith {
            feature: Some(f.into()),
            version: 2,
        })
    };
    let got = feed(&mut m, measurement(&s[0], "3", "IN2", 5), report("IN1")).await;
    assert!(
        matches!(&got, Ingested::Rejected { reason } if reason.contains("lobes mixed up")),
        "{got:?}"
    );
    let got = feed(&mut m, measurement(&s[1], "3", "IN1", 6), report("IN2")).await;
    assert!(matches!(got, Ingested::Rejected { .. }), "{got:?}");
    assert_eq!(states(&m), learned, "a swapped part was learned from");

    // A lobe the recipe does not have: rejected, nothing disturbed.
    let got = feed(&mut m, measurement(&s[0], "3", "EX9", 7), None).await;
    assert!(
        matches!(&got, Ingested::Rejected { reason } if reason.contains("\"EX9\"")),
        "{got:?}"
    );
    assert_eq!(states(&m), learned);

    // Correctly labelled parts go on learning, each in its own loop.
    assert_eq!(
        feed(&mut m, measurement(&s[0], "4", "IN1", 8), None).await,
        Ingested::Recorded
    );
    assert_eq!(
        feed(&mut m, measurement(&s[1], "4", "IN2", 9), None).await,
        Ingested::Recorded
    );
    let after = states(&m);
    assert_eq!((after[0].0, after[1].0), (2, 2));

    // The whole part back to its nominal tables (v1 of each), together; a version one lobe
    // lacks refuses all, before anything is pushed.
    let versions = |m: &MachineLoop| -> Vec<u64> {
        m.features()
            .iter()
            .map(|f| f.memory().in_force_version.map_or(0, |v| v.get()))
            .collect()
    };
    let before = versions(&m);
    let e = m
        .rollback_part(&[
            ("IN1".parse().unwrap(), ver(1)),
            ("IN2".parse().unwrap(), ver(99)),
        ])
        .await
        .unwrap_err();
    assert!(e.to_string().contains("version 99"), "{e}");
    assert_eq!(
        versions(&m),
        before,
        "nothing pushed when one version is missing"
    );
    let done = m
        .rollback_part(&[
            ("IN1".parse().unwrap(), ver(1)),
            ("IN2".parse().unwrap(), ver(1)),
        ])
        .await
        .unwrap();
    assert_eq!(done.len(), 2);
    let now = versions(&m);
    assert!(
        now[0] > before[0] && now[1] > before[1],
        "{before:?} → {now:?}"
    );
    for f in m.features() {
        assert!(f.memory().learning.correction_um.iter().all(|u| *u == 0.0));
    }
}

fn ver(n: u64) -> camloop::core::ids::TableVersion {
    camloop::core::ids::TableVersion::new(n).unwrap()
}
