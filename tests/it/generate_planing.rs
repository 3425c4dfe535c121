//! Ratio-coupled planing: rs274 runs the ISO program and every cutting move keeps
//! A = A_k + K·(X − X_start) with the return strokes lifted; a job interrupted at random
//! points and resumed from its state cuts every segment exactly once.

use crate::rs274_support;

use camloop::core::generate::dialect::{Decimals, Dialect, Form};
use camloop::core::generate::ir::{Axis, Expr, Motion, Stmt, expand};
use camloop::core::generate::planing::{
    JobState, PlaningError, PlaningJob, a_at, generate, render_sinumerik_table,
};
use rs274_support::{Canon, run_rs274};

fn job() -> PlaningJob {
    PlaningJob {
        name: "ROTOR_PLANE".to_owned(),
        segments: 6,
        ratio_deg_per_mm: 0.75,
        x_start_mm: 0.0,
        x_end_mm: 80.0,
        lead_in_mm: 8.0,
        z_cut_mm: -2.0,
        z_lift_mm: 5.0,
        feed_mm_min: 2000.0,
    }
}

#[test]
fn rs274_keeps_a_on_the_ratio_while_cutting_and_lifts_on_return() {
    let Some(rs) = rs274_support::rs274() else {
        panic!("rs274 (Debian linuxcnc-uspace) is not installed: .ci/run installs it");
    };
    let j = job();
    let p = generate(&j, &JobState::new(6)).unwrap();
    let canon = run_rs274(
        &rs,
        &Dialect::Iso.render(&p, Form::Loop, Decimals::default()),
        0.0,
    )
    .unwrap();
    let mut feeds = 0;
    for (i, m) in canon.iter().enumerate() {
        match *m {
            Canon::Feed { x, z, a, .. } => {
                assert_eq!(z, -2.0, "cutting depth");
                // Segment from A: the index is A − K·(X − X_start), a multiple of 60°.
                let index = a - j.ratio_deg_per_mm * (x - j.x_start_mm);
                let k = (index / 60.0).round();
                // 4 decimals printed on A: 0.5e-4° each side.
                assert!(
                    (index - 60.0 * k).abs() < 1.1e-4,
                    "move {i}: A = {a} at X = {x}"
                );
                assert!((a - a_at(&j, k as usize, x)).abs() < 1.1e-4);
                feeds += 1;
            }
            Canon::Rapid { x, z, .. } => {
                let prev_x = i.checked_sub(1).and_then(|p| match canon[p] {
                    Canon::Rapid { x, .. } | Canon::Feed { x, .. } => Some(x),
                    Canon::Arc { .. } => None,
                });
                if prev_x.is_some_and(|x0| (x - x0).abs() > 1e-9) {
                    assert_eq!(z, 5.0, "X moves in rapid only lifted (move {i})");
                }
            }
            Canon::Arc { .. } => panic!("no arcs in planing"),
        }
    }
    assert_eq!(feeds, 12, "lead-in and stroke for each of 6 segments");
}

/// A tiny deterministic generator for the interruption points.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self, n: usize) -> usize {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 33) as usize) % n
    }
}

/// The cutting stroke of a segment: a G1 ending at X end; its A says which segment.
fn stroke_segment(j: &PlaningJob, s: &Stmt) -> Option<usize> {
    let Stmt::Move {
        motion: Motion::Linear,
        words,
        ..
    } = s
    else {
        return None;
    };
    let get = |ax| {
        words.iter().find(|(a, _)| *a == ax).map(|(_, e)| match e {
            Expr::Num(v) => *v,
            _ => f64::NAN,
        })
    };
    let (x, a) = (get(Axis::X)?, get(Axis::A)?);
    (x == j.x_end_mm)
        .then(|| ((a - j.ratio_deg_per_mm * (x - j.x_start_mm)) / 60.0).round() as usize)
}

#[test]
fn interrupted_jobs_resume_at_the_first_unfinished_segment_and_cut_each_once() {
    let j = job();
    let mut rng = Lcg(0x5eed);
    for trial in 0..300 {
        let mut done_mark = 0u32; // the control's R50 / #50
        let mut complete_cuts = vec![0u32; 6];
        let mut runs = 0;
        loop {
            let state = JobState::from_mark(6, done_mark);
            let p = match generate(&j, &state) {
                Ok(p) => p,
                Err(PlaningError::Finished) => break,
                Err(e) => panic!("{e}"),
            };
            runs += 1;
            let blocks = expand(&p).body;
            // An interruption (feed hold and reset, power loss) stops a move under way;
            // blocks without motion (the mark after STOPRE / M66) take no time, so the
            // interruption falls inside a move, or the program runs to its end.
            let moves: Vec<usize> = (0..blocks.len())
                .filter(|&i| matches!(blocks[i], Stmt::Move { .. }))
                .collect();
            let stop = if runs < 4 {
                moves
                    .get(rng.next(moves.len() + 1))
                    .copied()
                    .unwrap_or(blocks.len())
            } else {
                blocks.len()
            };
            for b in &blocks[..stop] {
                if let Some(k) = stroke_segment(&j, b) {
                    complete_cuts[k] += 1;
                }
                if let Stmt::Mark { value, .. } = b {
                    done_mark = *value as u32;
                }
            }
            assert!(runs < 20, "trial {trial} does not finish");
        }
        assert_eq!(
            complete_cuts,
            vec![1; 6],
            "trial {trial}: every segment exactly once"
        );
    }
}

#[test]
fn golden_programs_and_refusals() {
    let j = job();
    let resume = JobState::from_mark(6, 4);
    let p = generate(&j, &resume).unwrap();
    insta::assert_snapshot!(
        "planing_resume_iso",
        Dialect::Iso.render(&p, Form::Expanded, Decimals::default())
    );
    insta::assert_snapshot!(
        "planing_resume_sinumerik_table",
        render_sinumerik_table(&j, &resume, 3).unwrap()
    );
    let mut bad = job();
    bad.z_lift_mm = -3.0;
    assert!(matches!(
        generate(&bad, &JobState::new(6)),
        Err(PlaningError::Value {
            field: "z lift",
            ..
        })
    ));
    assert!(matches!(
        generate(&j, &JobState::from_mark(6, 6)),
        Err(PlaningError::Finished)
    ));
}
