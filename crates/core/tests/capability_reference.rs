//! The capability statistics against an independent implementation: the repository's
//! `tests/capability/reference.py` (numpy and scipy, written from the manual's formulas with
//! scipy's own distributions, quantiles and optimisers) on four data sets: normal, one-sided
//! (folded-normal-like and log-normal), and drifting. Every number must agree to a relative
//! 5e-4 (better than 3 significant figures).
//!
//! Skips with a line on stderr when python3 with scipy is missing, unless
//! `CAMLOOP_REQUIRE_SCIPY=1` (CI sets it and installs scipy).

use camloop_core::capability::{Capability, Limits, Model, assess};
use serde_json::{Value, json};
use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};

/// Agreement asked for: relative, or absolute below this for values near zero.
const RELATIVE: f64 = 5e-4;
const ABSOLUTE: f64 = 1e-9;

/// splitmix64 and Box–Muller: the data sets are the same on every run and platform.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn gaussian(&mut self) -> f64 {
        let u = self.uniform().max(1e-300);
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * self.uniform()).cos()
    }
}

struct DataSet {
    name: &'static str,
    values: Vec<f64>,
    limits: Limits,
    bounded_at_zero: bool,
}

fn data_sets() -> Vec<DataSet> {
    let mut rng = Rng(27);
    let normal: Vec<f64> = (0..50).map(|_| 0.2 + 1.1 * rng.gaussian()).collect();
    // Max |error| of a converged loop: |N(0.6, 0.35²)| µm.
    let folded: Vec<f64> = (0..60)
        .map(|_| (0.6 + 0.35 * rng.gaussian()).abs())
        .collect();
    let skewed: Vec<f64> = (0..40)
        .map(|_| (0.2 + 0.4 * rng.gaussian()).exp())
        .collect();
    // A size drifting 0.05 µm a part (wheel wear) under 0.8 µm noise.
    let drifting: Vec<f64> = (0..80)
        .map(|i| -2.0 + 0.05 * f64::from(i) + 0.8 * rng.gaussian())
        .collect();
    let both = |l: f64, u: f64| Limits {
        lower: Some(l),
        upper: Some(u),
    };
    let upper = |u: f64| Limits {
        lower: None,
        upper: Some(u),
    };
    vec![
        DataSet {
            name: "normal",
            values: normal,
            limits: both(-4.0, 4.0),
            bounded_at_zero: false,
        },
        DataSet {
            name: "one-sided folded",
            values: folded,
            limits: upper(2.0),
            bounded_at_zero: true,
        },
        DataSet {
            name: "one-sided skewed",
            values: skewed,
            limits: upper(5.0),
            bounded_at_zero: true,
        },
        DataSet {
            name: "drifting",
            values: drifting,
            limits: both(-5.0, 5.0),
            bounded_at_zero: false,
        },
    ]
}

fn scipy_available() -> bool {
    Command::new("python3")
        .args(["-c", "import scipy, numpy"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn reference(sets: &[DataSet]) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/capability/reference.py");
    let input = json!({"datasets": sets.iter().map(|d| json!({
        "name": d.name, "values": d.values, "lower": d.limits.lower,
        "upper": d.limits.upper, "bounded_at_zero": d.bounded_at_zero,
    })).collect::<Vec<_>>()});
    let mut child = Command::new("python3")
        .arg(&script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 runs");
    child
        .stdin
        .take()
        .expect("piped")
        .write_all(input.to_string().as_bytes())
        .expect("the script reads its input");
    let out = child.wait_with_output().expect("the script ends");
    assert!(out.status.success(), "{} failed", script.display());
    serde_json::from_slice(&out.stdout).expect("the script prints JSON")
}

/// Our numbers under the names the reference uses.
fn ours(c: &Capability) -> Vec<(String, f64)> {
    let mut out: Vec<(&'static str, f64)> = vec![
        ("mean", c.mean),
        ("sigma_within", c.sigma_within),
        ("sigma_overall", c.sigma_overall),
    ];
    let mut fits = Vec::new();
    if let Model::Fitted { candidates } = &c.model {
        out.push(("log_likelihood", candidates[0].log_likelihood));
        // Every candidate's likelihood, so the choice is checked, not only the winner.
        fits = candidates
            .iter()
            .map(|f| (format!("candidates/{}", f.fitted.name()), f.log_likelihood))
            .collect();
    }
    if let Some(ix) = &c.indices {
        out.extend([
            ("cpk", ix.cpk.value),
            ("cpk_lower_95", ix.cpk.lower_95),
            ("ppk", ix.ppk.value),
            ("ppk_lower_95", ix.ppk.lower_95),
            ("expected_share_out", ix.expected_share_out),
            ("observed_share_out", ix.observed_share_out),
        ]);
        if let (Some(cp), Some(pp)) = (ix.cp, ix.pp) {
            out.extend([
                ("cp", cp.value),
                ("cp_lower_95", cp.lower_95),
                ("pp", pp.value),
                ("pp_lower_95", pp.lower_95),
            ]);
        }
    }
    out.into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .chain(fits)
        .collect()
}

#[test]
fn capability_matches_the_scipy_reference() {
    if !scipy_available() {
        assert!(
            std::env::var("CAMLOOP_REQUIRE_SCIPY").as_deref() != Ok("1"),
            "CAMLOOP_REQUIRE_SCIPY=1 but python3 with scipy and numpy is missing"
        );
        eprintln!("skipped: python3 with scipy and numpy not found (pip install scipy)");
        return;
    }
    let sets = data_sets();
    let reference = reference(&sets);
    let mut worst = 0.0f64;
    let mut compared = 0;
    for (d, r) in sets
        .iter()
        .zip(reference["results"].as_array().expect("results"))
    {
        let c = assess(&d.values, d.limits, d.bounded_at_zero).expect("a window of parts");
        assert_eq!(
            r["model"].as_str(),
            Some(c.model.name()),
            "{}: model",
            d.name
        );
        assert!(c.indices.is_some(), "{}: indices", d.name);
        eprintln!("{}: n {}, model {}", d.name, c.n, c.model.name());
        for (key, value) in ours(&c) {
            let expected = r
                .pointer(&format!("/{key}"))
                .and_then(Value::as_f64)
                .unwrap_or_else(|| panic!("{}: reference lacks {key}", d.name));
            let diff = (value - expected).abs();
            let scale = value.abs().max(expected.abs());
            assert!(
                diff <= RELATIVE * scale || diff <= ABSOLUTE,
                "{} {key}: camloop {value} scipy {expected}",
                d.name
            );
            if scale > 0.0 {
                worst = worst.max(diff / scale);
            }
            compared += 1;
        }
    }
    eprintln!("{compared} numbers agree with scipy; largest relative difference {worst:.1e}");
}
