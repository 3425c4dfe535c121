//! The serial adapter through a real pseudo-terminal: the test writes the line protocol into
//! the master end, the adapter opens the slave end by its path with tokio-serial. The text
//! is a fixture written by tools/encode_text_fixtures.py (checksum from Python's zlib).

use crate::fixture_support::{encoder_lift_mm, fixture_text};

use camloop::core::measure::RawMeasurement;
use camloop::gauge::{SerialEvent, SerialGauge, decode_serial_text};
use tokio::io::AsyncWriteExt;
use tokio_serial::SerialPort;

fn assert_fixture_measurement(m: &RawMeasurement) {
    assert_eq!(
        (
            m.header.machine.as_str(),
            m.header.part.as_str(),
            m.header.lobe.as_str()
        ),
        ("M3", "P1234", "L2")
    );
    assert_eq!((m.header.revolutions, m.header.points_per_rev), (3, 360));
    assert_eq!(m.samples.len(), 1080);
    for (n, s) in m.samples.iter().enumerate() {
        let n = u32::try_from(n).expect("small");
        assert_eq!((s.revolution, s.angle_index), (n / 360, n % 360));
        // Printed with 6 decimals: within half a nm, plus 1e-12 for binary parsing.
        let expected = encoder_lift_mm(s.revolution, s.angle_index, 360);
        assert!(
            (s.lift_mm - expected).abs() <= 0.5e-6 + 1e-12,
            "{} vs {expected}",
            s.lift_mm
        );
    }
}

#[test]
fn the_python_written_fixture_decodes_with_a_matching_checksum() {
    let events = decode_serial_text(&fixture_text("gauge_serial_3x360.txt"), "fixture");
    assert_eq!(events.len(), 1, "{events:?}");
    let SerialEvent::Measurement(m) = &events[0] else {
        panic!("{events:?}")
    };
    assert_fixture_measurement(m);
}

#[tokio::test]
async fn a_measurement_arrives_through_a_pseudo_terminal() {
    let (mut master, slave) = tokio_serial::SerialStream::pair().expect("pty pair");
    let path = slave.name().expect("the slave end has a device path");
    // pair() holds the slave end with an exclusive lock; close it so the adapter opens the
    // device by its path like any serial port (the master keeps the pty alive).
    drop(slave);
    let mut gauge = SerialGauge::open(&path, 115_200).expect("opens the pty by path");

    // Noise before the measurement, then the fixture; written from a task because the pty
    // buffer holds only a few kB and the adapter must drain it meanwhile.
    let text = format!("garbage line\n{}", fixture_text("gauge_serial_3x360.txt"));
    let writer = tokio::spawn(async move {
        master.write_all(text.as_bytes()).await.expect("write");
        master.flush().await.expect("flush");
        master
    });

    let first = gauge.next_event().await.expect("read").expect("event");
    let SerialEvent::Problem(p) = &first else {
        panic!("{first:?}")
    };
    assert_eq!(
        p.to_string(),
        "line 1: unknown record \"garbage\" (expected START, S or END)"
    );
    let second = gauge.next_event().await.expect("read").expect("event");
    let SerialEvent::Measurement(m) = &second else {
        panic!("{second:?}")
    };
    assert_eq!(m.origin, path);
    assert_fixture_measurement(m);
    drop(writer.await.expect("writer task"));
}

#[tokio::test]
async fn opening_a_missing_port_names_it() {
    let err = SerialGauge::open("/dev/camloop-no-such-tty", 9600).expect_err("no such port");
    let msg = err.to_string();
    assert!(
        msg.starts_with("serial port /dev/camloop-no-such-tty unavailable: "),
        "{msg}"
    );
}
