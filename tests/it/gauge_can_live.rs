//! The live CAN adapter. This kernel has no SocketCAN, so opening must fail with a clear
//! error (never panic); the listener itself is driven by a recorded log through the same
//! `FrameSource` interface the socket implements.

use crate::fixture_support::fixture_text;

use camloop::gauge::{
    AssemblyProblem, CanEvent, CanGauge, CandumpReplay, DiscardReason, GaugeDbc,
    read_candump_measurements,
};

#[tokio::test]
async fn opening_a_missing_interface_is_a_clear_error() {
    let err = CanGauge::open("camloopcan9", GaugeDbc::builtin()).expect_err("no such interface");
    let msg = err.to_string();
    assert!(
        msg.starts_with("can interface camloopcan9 unavailable: "),
        "{msg}"
    );
    // The kernel says why: no such device, or (where it has no CAN at all) no protocol
    // support; each comes with a hint for the operator.
    assert!(
        msg.contains("(no network interface of that name")
            || msg.contains("(kernel has no SocketCAN support?)"),
        "{msg}"
    );
}

#[tokio::test]
async fn opening_a_non_can_interface_is_a_clear_error() {
    // The loopback interface exists everywhere and is never a CAN interface.
    let err = CanGauge::open("lo", GaugeDbc::builtin()).expect_err("lo is not CAN");
    let msg = err.to_string();
    assert!(msg.starts_with("can interface lo unavailable: "), "{msg}");
}

#[test]
fn opening_outside_a_runtime_is_an_error_not_a_panic() {
    let err = CanGauge::open("can0", GaugeDbc::builtin()).expect_err("no runtime");
    assert_eq!(
        err.to_string(),
        "can interface can0 unavailable: no tokio runtime to drive the socket"
    );
}

#[tokio::test]
async fn the_listener_hears_what_the_log_replay_reads() {
    let text = fixture_text("gauge_cutoff.log");
    let mut gauge = CanGauge::new(CandumpReplay::new(&text), GaugeDbc::builtin(), "bus");
    let mut events = Vec::new();
    while let Some(e) = gauge.next_event().await.expect("a replay cannot fail") {
        events.push(e);
    }
    assert_eq!(gauge.foreign_frames, 11);
    let report = read_candump_measurements(&text, &GaugeDbc::builtin(), "bus");
    assert_eq!(report.measurements.len(), 1);
    // Same outcome as the log reader: stray samples, lobe 1 cut off, lobe 2 complete and
    // identical, lobe 3 aborted by the gauge.
    assert_eq!(events.len(), 4, "{events:?}");
    assert_eq!(
        events[0],
        CanEvent::Problem(AssemblyProblem::SamplesWithoutStart { count: 2 })
    );
    assert!(matches!(
        &events[1],
        CanEvent::Problem(AssemblyProblem::Discarded {
            samples_received: 500,
            reason: DiscardReason::CutOffByNewStart,
            ..
        })
    ));
    assert_eq!(
        events[2],
        CanEvent::Measurement(report.measurements[0].clone())
    );
    assert!(matches!(
        &events[3],
        CanEvent::Problem(AssemblyProblem::Discarded {
            samples_received: 10,
            reason: DiscardReason::GaugeStatus(2),
            ..
        })
    ));
}

#[tokio::test]
async fn undecodable_gauge_frames_are_reported_and_the_stream_goes_on() {
    let text = "\
(1.0) can0 5A1#0000
(1.1) can0 5A0#0030810004D20001
(1.2) can0 5A1#000000E8030000
(1.3) can0 5A2#00
";
    let mut gauge = CanGauge::new(CandumpReplay::new(text), GaugeDbc::builtin(), "bus");
    let first = gauge.next_event().await.expect("replay").expect("event");
    let CanEvent::BadFrame(e) = first else {
        panic!("{first:?}")
    };
    assert_eq!(e.to_string(), "GaugeSample frame has 2 data bytes, needs 7");
    let second = gauge.next_event().await.expect("replay").expect("event");
    let CanEvent::Measurement(m) = second else {
        panic!("{second:?}")
    };
    assert_eq!((m.header.revolutions, m.header.points_per_rev), (1, 1));
    assert_eq!(m.origin, "bus");
    // 1000 raw × 0.0001 mm; 1e-12 covers the binary factor.
    assert!((m.samples[0].lift_mm - 0.1).abs() < 1e-12);
    assert_eq!(gauge.next_event().await.expect("replay"), None);
}
