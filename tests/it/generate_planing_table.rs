//! The planer's SINUMERIK curve-table form (A and Z following the ram's X through
//! `CTABDEF` tables and `LEADON`) run as the control couples it: the tables read from the
//! program's text, each stroke's A and Z taken from them at every breakpoint of X, and the
//! cuts checked against the face and the ratio exactly as rs274's cuts of the ISO program are.
//!
//! The evaluator here is test support, not product code: it knows the blocks this form
//! writes (`CTABDEF … CTABEND`, `LEADON`/`LEADOF`, `$SA_LEAD_OFFSET_OUT_POS`, `IF R50>=k
//! GOTOF`, `R50=`, `G0`/`G1` with `X= A= Z=`) and refuses anything else it meets.

use std::collections::HashMap;

use crate::generate_planing::{check_cuts, job};
use camloop::core::generate::planing::coupled::render_sinumerik_table;

/// A curve table: the leading axis's values and the following axis's, as written.
struct Table {
    follow: char,
    points: Vec<(f64, f64)>,
}

impl Table {
    /// The following axis at `x`, linear between the written points (`G1` segments).
    fn at(&self, x: f64) -> f64 {
        let p = &self.points;
        let i = p
            .windows(2)
            .position(|w| x <= w[1].0 + 1e-12)
            .unwrap_or(p.len() - 2);
        let (a, b) = (p[i], p[i + 1]);
        a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0)
    }
}

/// `X=1.5 A=-6` → [('X', 1.5), ('A', -6.0)]; other words (G1, F…) left out.
fn words(line: &str) -> Vec<(char, f64)> {
    line.split_whitespace()
        .filter_map(|w| {
            let (axis, v) = w.split_once('=')?;
            let axis = axis.chars().next().filter(|_| axis.len() == 1)?;
            Some((axis, v.parse().ok()?))
        })
        .collect()
}

/// Runs the table form with R50 preset to `r50`; the feed moves as (X, A, Z) and R50 after.
fn run(text: &str, r50: f64) -> (Vec<(f64, f64, f64)>, f64) {
    let lines: Vec<&str> = text
        .lines()
        .map(|l| l.split(';').next().unwrap().trim())
        .collect();
    let labels: HashMap<&str, usize> = lines
        .iter()
        .enumerate()
        .filter_map(|(i, l)| Some((l.strip_suffix(':')?, i)))
        .collect();
    let (mut tables, mut coupled) = (HashMap::new(), Vec::<(char, u32)>::new());
    let (mut pos, mut offset_a, mut r50) = (
        HashMap::from([('X', 0.0), ('A', 0.0), ('Z', 0.0)]),
        0.0,
        r50,
    );
    let mut feeds = Vec::new();
    let mut pc = 0;
    while pc < lines.len() {
        let l = lines[pc];
        pc += 1;
        if let Some(def) = l.strip_prefix("CTABDEF(") {
            let args: Vec<&str> = def.trim_end_matches(')').split(',').collect();
            let (follow, lead) = (
                args[0].chars().next().unwrap(),
                args[1].chars().next().unwrap(),
            );
            let mut points = Vec::new();
            while lines[pc] != "CTABEND" {
                let w: HashMap<char, f64> = words(lines[pc]).into_iter().collect();
                points.push((w[&lead], w[&follow]));
                pc += 1;
            }
            pc += 1;
            tables.insert(args[2].parse::<u32>().unwrap(), Table { follow, points });
        } else if let Some(cond) = l.strip_prefix("IF R50>=") {
            let (k, label) = cond.split_once(" GOTOF ").unwrap();
            if r50 >= k.parse::<f64>().unwrap() {
                pc = labels[label];
            }
        } else if let Some(v) = l.strip_prefix("$SA_LEAD_OFFSET_OUT_POS[A]=") {
            offset_a = v.parse().unwrap();
        } else if let Some(args) = l.strip_prefix("LEADON(") {
            let args: Vec<&str> = args.trim_end_matches(')').split(',').collect();
            assert_eq!(args[1], "X", "the ram leads: {l}");
            coupled.push((args[0].chars().next().unwrap(), args[2].parse().unwrap()));
        } else if let Some(args) = l.strip_prefix("LEADOF(") {
            let follow = args.chars().next().unwrap();
            coupled.retain(|c| c.0 != follow);
        } else if let Some(v) = l.strip_prefix("R50=") {
            r50 = v.parse().unwrap();
        } else if l.starts_with("G0 ") || l.starts_with("G1 ") {
            let target: HashMap<char, f64> = words(l).into_iter().collect();
            let x1 = target.get(&'X').copied().unwrap_or(pos[&'X']);
            let x0 = pos[&'X'];
            // Under the coupling the followers take the tables' values at every breakpoint
            // the ram passes, and at its end.
            let mut xs: Vec<f64> = coupled
                .iter()
                .flat_map(|c| tables[&c.1].points.iter().map(|p| p.0))
                .filter(|&x| (x - x0) * (x1 - x0) > 0.0 && (x - x0).abs() < (x1 - x0).abs())
                .collect();
            xs.push(x1);
            xs.sort_by(|a, b| ((a - x0).abs()).total_cmp(&(b - x0).abs()));
            xs.dedup();
            for x in xs {
                pos.insert('X', x);
                for (&k, &v) in &target {
                    if k != 'X' && !coupled.iter().any(|c| c.0 == k) {
                        pos.insert(k, v);
                    }
                }
                for c in &coupled {
                    let t = &tables[&c.1];
                    let off = if t.follow == 'A' { offset_a } else { 0.0 };
                    pos.insert(t.follow, t.at(x) + off);
                }
                if l.starts_with("G1 ") {
                    feeds.push((pos[&'X'], pos[&'A'], pos[&'Z']));
                }
            }
        } else {
            let known = l.is_empty()
                || l.starts_with("%_N_")
                || l.ends_with(':')
                || ["G17", "G54", "T1", "G94", "M8", "M9", "M30", "STOPRE"]
                    .iter()
                    .any(|k| l.starts_with(k))
                || (l.starts_with('M') && l[1..].chars().all(|c| c.is_ascii_digit()));
            assert!(known, "the table form's evaluator does not know `{l}`");
        }
    }
    (feeds, r50)
}

#[test]
fn the_table_form_coupled_as_the_control_couples_it_cuts_the_face_on_the_ratio() {
    let j = job();
    let text = render_sinumerik_table(&j, 3).unwrap();
    let (feeds, after) = run(&text, 0.0);
    let (done, worst_um) = check_cuts(&j, &feeds);
    eprintln!("planing table form: worst chord error {worst_um:.3} um");
    assert_eq!(done, vec![0, 1, 2, 3, 4, 5], "every arc, in order");
    // The same bound as rs274's run of the ISO program: 2 µm plus the written rounding.
    assert!(worst_um < 2.1, "worst {worst_um} um");
    assert!(
        worst_um > 0.5,
        "the chords use the tolerance ({worst_um} um)"
    );
    assert_eq!(after, 0.0, "a finished job leaves the mark cleared");
    // Resumed after four arcs: only the fifth and sixth are cut.
    let (feeds, after) = run(&text, 4.0);
    assert_eq!(check_cuts(&j, &feeds).0, vec![4, 5]);
    assert_eq!(after, 0.0);
}
