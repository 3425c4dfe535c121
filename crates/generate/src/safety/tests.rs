//! Each rule of the safety check fires on a program that breaks it, and only then.

use super::*;
use crate::ir::{Program, Stmt};
use crate::setup::Setup;

fn mv(motion: Motion, words: &[(Axis, f64)], feed: Option<f64>) -> Stmt {
    Stmt::Move {
        motion,
        words: words.iter().map(|&(a, v)| (a, Expr::Num(v))).collect(),
        feed,
    }
}

fn program(plane: Plane, body: Vec<Stmt>) -> Program {
    Program {
        name: "T".to_owned(),
        plane,
        vars: Vec::new(),
        comments: Vec::new(),
        body,
    }
}

/// A lathe program: set-up, `cuts`, end.
fn lathe(cuts: Vec<Stmt>) -> Program {
    let s = Setup::turning();
    let mut body = s.start();
    body.extend(cuts);
    body.extend(s.end());
    program(Plane::Zx, body)
}

#[test]
fn a_complete_lathe_program_passes_and_reports_what_it_saw() {
    let p = lathe(vec![
        mv(Motion::Rapid, &[(Axis::X, 30.0), (Axis::Z, 2.0)], None),
        mv(
            Motion::Linear,
            &[(Axis::X, 20.0), (Axis::Z, 0.0)],
            Some(0.1),
        ),
        mv(Motion::Linear, &[(Axis::Z, -20.0)], None),
        mv(Motion::Rapid, &[(Axis::X, 30.0)], None),
    ]);
    let r = check(&p, &Rules::lathe()).unwrap();
    assert_eq!((r.moves, r.cutting_moves), (4, 2));
    assert_eq!(r.min_x_mm, Some(20.0));
}

#[test]
fn a_cut_before_the_tool_spindle_or_feed_mode_is_refused_by_name() {
    let s = Setup::turning();
    let cut = mv(Motion::Linear, &[(Axis::X, 20.0)], Some(0.1));
    // Cut first, set-up after: all three are missing and the F has no unit.
    let mut body = vec![cut.clone()];
    body.extend(s.start());
    body.extend(s.end());
    let v = check(&program(Plane::Zx, body), &Rules::lathe()).unwrap_err();
    let missing: Vec<&str> = v
        .iter()
        .filter_map(|e| match e {
            Violation::CutBeforeSetup { missing, block: 1 } => Some(*missing),
            _ => None,
        })
        .collect();
    assert_eq!(
        missing,
        ["the tool call", "the spindle start", "the feed mode"]
    );
    assert!(v.contains(&Violation::FeedBeforeMode { block: 1 }), "{v:?}");
    // Without the spindle start only: that one is named.
    let mut start = s.start();
    start.retain(|st| !matches!(st, Stmt::Machine(MachineStmt::SpindleOn(_))));
    let mut body = start;
    body.push(cut);
    body.extend(s.end());
    let v = check(&program(Plane::Zx, body), &Rules::lathe()).unwrap_err();
    assert_eq!(
        v,
        [Violation::CutBeforeSetup {
            block: 6,
            missing: "the spindle start"
        }]
    );
}

#[test]
fn a_cut_without_a_feed_or_after_the_spindle_stops_is_refused() {
    let p = lathe(vec![mv(Motion::Linear, &[(Axis::X, 20.0)], None)]);
    let v = check(&p, &Rules::lathe()).unwrap_err();
    assert!(matches!(v[..], [Violation::NoFeed { .. }]), "{v:?}");
    let s = Setup::turning();
    let mut body = s.start();
    body.push(mv(Motion::Linear, &[(Axis::X, 20.0)], Some(0.1)));
    body.extend(s.end());
    body.push(mv(Motion::Linear, &[(Axis::Z, -5.0)], None));
    let v = check(&program(Plane::Zx, body), &Rules::lathe()).unwrap_err();
    assert!(matches!(v[..], [Violation::CutAfterStop { .. }]), "{v:?}");
}

#[test]
fn behind_the_axis_on_a_move_and_inside_an_arc() {
    let p = lathe(vec![
        mv(Motion::Rapid, &[(Axis::X, 10.0), (Axis::Z, 0.0)], None),
        mv(Motion::Rapid, &[(Axis::X, -0.98)], None),
    ]);
    let v = check(&p, &Rules::lathe()).unwrap_err();
    assert!(
        matches!(v[..], [Violation::BehindAxis { x_mm, .. }] if x_mm == -0.98),
        "{v:?}"
    );
    // A half circle of radius 5 about (z −5, x 3): from (0, 3) to (−10, 3). Its lowest point
    // x = −2 lies on the arc going one way round and not the other: G2 runs clockwise in
    // (z right, x up), from angle 0° through −90°, the bottom.
    let arc = |m| {
        lathe(vec![
            mv(Motion::Rapid, &[(Axis::X, 3.0), (Axis::Z, 0.0)], None),
            mv(Motion::Linear, &[(Axis::X, 3.0)], Some(0.1)),
            mv(
                m,
                &[(Axis::X, 3.0), (Axis::Z, -10.0), (Axis::K, -5.0)],
                None,
            ),
        ])
    };
    let v = check(&arc(Motion::ArcCw), &Rules::lathe()).unwrap_err();
    assert!(
        matches!(v[..], [Violation::BehindAxis { x_mm, .. }] if (x_mm + 2.0).abs() < 1e-12),
        "{v:?}"
    );
    let r = check(&arc(Motion::ArcCcw), &Rules::lathe()).unwrap();
    assert_eq!(r.min_x_mm, Some(3.0));
    // A milling program has no axis to stay above.
    assert!(check(&arc(Motion::ArcCw), &Rules::default()).is_ok());
}

fn milling(cuts: Vec<Stmt>) -> Program {
    let s = Setup::milling();
    let mut body = s.start();
    body.extend(cuts);
    body.extend(s.end());
    program(Plane::Xy, body)
}

#[test]
fn a_rotary_axis_turns_only_with_the_tool_clear_or_coupled_to_the_cut() {
    // Turn-mill: clear 60 mm from the C axis in X-Y.
    let rules = Rules {
        min_x_mm: None,
        rotary: vec![Rotary {
            axis: Axis::C,
            coupled_cut: false,
        }],
        clear: vec![Clear::RadiusAtLeast { mm: 60.0 }],
        no_spindle: false,
    };
    let engaged = milling(vec![
        mv(Motion::Rapid, &[(Axis::X, 52.0), (Axis::Y, 0.0)], None),
        mv(Motion::Rapid, &[(Axis::C, 30.0)], None),
    ]);
    let v = check(&engaged, &rules).unwrap_err();
    assert_eq!(
        v,
        [Violation::RotaryEngaged {
            block: 7,
            axis: 'C'
        }]
    );
    let clear = milling(vec![
        mv(Motion::Rapid, &[(Axis::X, 60.0), (Axis::Y, 5.0)], None),
        mv(Motion::Rapid, &[(Axis::C, 30.0)], None),
    ]);
    assert_eq!(check(&clear, &rules).unwrap().rotary_moves, 1);
    // Unknown position (C before any X or Y) is not clear.
    let first = milling(vec![mv(Motion::Rapid, &[(Axis::C, 30.0)], None)]);
    assert!(check(&first, &rules).is_err());
    // Planing: A follows X in the cut; an index of A with Z down is refused.
    let planing = |coupled_cut| Rules {
        min_x_mm: None,
        rotary: vec![Rotary {
            axis: Axis::A,
            coupled_cut,
        }],
        clear: vec![Clear::AtLeast {
            axis: Axis::Z,
            mm: 5.0,
        }],
        no_spindle: false,
    };
    let stroke = milling(vec![
        mv(Motion::Rapid, &[(Axis::Z, 5.0)], None),
        mv(Motion::Rapid, &[(Axis::X, -8.0), (Axis::A, -6.0)], None),
        mv(Motion::Rapid, &[(Axis::Z, -2.0)], None),
        mv(
            Motion::Linear,
            &[(Axis::X, 80.0), (Axis::A, 60.0)],
            Some(2000.0),
        ),
        mv(Motion::Rapid, &[(Axis::Z, 5.0)], None),
    ]);
    assert!(check(&stroke, &planing(true)).is_ok());
    let v = check(&stroke, &planing(false)).unwrap_err();
    assert_eq!(
        v,
        [Violation::RotaryEngaged {
            block: 9,
            axis: 'A'
        }]
    );
    let index_down = milling(vec![
        mv(Motion::Rapid, &[(Axis::Z, -2.0)], None),
        mv(Motion::Rapid, &[(Axis::A, 60.0)], None),
    ]);
    assert!(check(&index_down, &planing(true)).is_err());
}

#[test]
fn the_end_must_stop_spindle_and_coolant() {
    let s = Setup::turning();
    let mut body = s.start();
    body.push(mv(Motion::Rapid, &[(Axis::X, 30.0)], None));
    let v = check(&program(Plane::Zx, body.clone()), &Rules::lathe()).unwrap_err();
    assert_eq!(v, [Violation::SpindleLeftOn, Violation::CoolantLeftOn]);
    body.push(Stmt::Machine(MachineStmt::SpindleOff));
    let v = check(&program(Plane::Zx, body), &Rules::lathe()).unwrap_err();
    assert_eq!(v, [Violation::CoolantLeftOn]);
}
