//! `camloop contour`, `turnmill` and `planing` as a user runs them: real binary, real
//! files, one-line refusals that leave nothing behind.

use crate::cli_support;

use cli_support::{assert_nothing_written, camloop, camloop_ok, refusal, repo, stderr};

#[test]
fn contour_writes_the_program_and_reports_the_fixed_step_figure() {
    let dir = tempfile::tempdir().unwrap();
    let out = camloop_ok(
        &[
            "contour",
            "ellipse",
            "--centre-z-mm",
            "-30",
            "--centre-x-mm",
            "10",
            "--a-mm",
            "30",
            "--b-mm",
            "20",
            "--start-deg",
            "10",
            "--end-deg",
            "170",
            "--dialect",
            "iso",
            "--out",
            "e.ngc",
        ],
        dir.path(),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("117 chords"), "{stdout}");
    assert!(stdout.contains("fixed step needs 130 chords"), "{stdout}");
    let text = std::fs::read_to_string(dir.path().join("e.ngc")).unwrap();
    assert!(
        text.contains("o104 do") && text.contains("G42 G1"),
        "{text}"
    );
}

/// A sine contour of 2 mm amplitude on a 20 mm wavelength along 40 mm of Z: its concave
/// radius is 5.066 mm.
const SINE: [&str; 12] = [
    "contour",
    "sine",
    "--mean-x-mm",
    "20",
    "--amplitude-mm",
    "2",
    "--wavelength-mm",
    "20",
    "--z-start-mm",
    "0",
    "--z-end-mm",
    "-40",
];

#[test]
fn contour_refusal_is_one_line_with_the_reason_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = camloop(
        &[&SINE[..], &["--nose-radius-mm", "6", "--out", "s.mpf"]].concat(),
        dir.path(),
    );
    let err = refusal(&out);
    assert!(
        err.contains("nose radius 6 mm is larger than the concave radius 5.066"),
        "{err}"
    );
    assert_nothing_written(dir.path());
    let out = camloop(
        &[&SINE[..], &["--tolerance-um", "0.1"]].concat(),
        dir.path(),
    );
    assert!(
        stderr(&out).contains("below what the control can hold"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn contour_r_params_form_writes_the_constants_and_refuses_a_contour_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = camloop_ok(
        &[&SINE[..], &["--form", "r-params", "--out", "s.mpf"]].concat(),
        dir.path(),
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("R-parameter form,"), "{stdout}");
    let text = std::fs::read_to_string(dir.path().join("s.mpf")).unwrap();
    assert!(
        !text.contains("DEF ") && text.contains("\nR12=") && text.contains("GOTOB LOOP_4"),
        "{text}"
    );
    let file = repo("config/contour-802d-aa5.toml");
    let out = camloop(
        &[
            "contour",
            "file",
            "--contour",
            &file,
            "--form",
            "r-params",
            "--out",
            "f.mpf",
        ],
        dir.path(),
    );
    assert!(
        refusal(&out).contains("the R-parameter form is for a single curve"),
        "{}",
        stderr(&out)
    );
    assert!(!dir.path().join("f.mpf").exists());
}

#[test]
fn contour_file_writes_main_and_subprogram_and_refuses_cycle95_for_iso() {
    let dir = tempfile::tempdir().unwrap();
    let file = repo("config/contour-802d-aa5.toml");
    let out = camloop_ok(
        &[
            "contour",
            "file",
            "--contour",
            &file,
            "--out",
            "aa5.mpf",
            "--diameter",
        ],
        dir.path(),
    );
    let main = std::fs::read_to_string(dir.path().join("aa5.mpf")).unwrap();
    let sub = std::fs::read_to_string(dir.path().join("aa5_c.spf")).unwrap();
    assert!(main.contains("DIAMON ; X as a diameter") && main.contains("AA5_C ; contour"));
    assert!(
        sub.starts_with("%_N_AA5_C_SPF") && sub.ends_with("RET\n"),
        "{sub}"
    );
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("safety check"), "{stdout}");
    let bad = dir.path().join("c95.toml");
    let t = std::fs::read_to_string(&file).unwrap().replace(
        "kind = \"passes\"\n# Bar radius, mm (a 50 mm bar).\nblank_radius_mm = 25.0",
        "kind = \"cycle95\"",
    );
    std::fs::write(&bad, t).unwrap();
    let out = camloop(
        &[
            "contour",
            "file",
            "--contour",
            bad.to_str().unwrap(),
            "--dialect",
            "iso",
            "--out",
            "x.ngc",
        ],
        dir.path(),
    );
    assert!(
        refusal(&out).contains("roughing by CYCLE95 is SINUMERIK's"),
        "{}",
        stderr(&out)
    );
    assert!(!dir.path().join("x.ngc").exists());
}

#[test]
fn turnmill_job_file_to_program_and_unknown_keys_refused_with_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let job = repo("config/turnmill-crank.toml");
    camloop_ok(&["turnmill", "--job", &job, "--out", "c.mpf"], dir.path());
    let text = std::fs::read_to_string(dir.path().join("c.mpf")).unwrap();
    assert!(
        text.contains("G94 ; F in mm per minute") && text.contains("M5 ; spindle off"),
        "{text}"
    );
    // One C move per feature, each at the park point.
    assert_eq!(text.matches("\nG0 C=").count(), 4, "{text}");
    let bad = dir.path().join("bad.toml");
    let mut t = std::fs::read_to_string(&job).unwrap();
    t = t.replace("safety_deg = 3.0", "safety_deg = 3.0\nsafety = 3.0");
    std::fs::write(&bad, t).unwrap();
    let out = camloop(
        &["turnmill", "--job", bad.to_str().unwrap(), "--out", "d.mpf"],
        dir.path(),
    );
    let err = stderr(&out);
    assert!(!out.status.success());
    assert!(
        err.contains("bad.toml") && err.contains("line 73") && err.contains("safety"),
        "{err}"
    );
    assert!(!dir.path().join("d.mpf").exists());
}

#[test]
fn planing_from_a_card_and_from_options_saved_as_a_card_that_gives_the_same_program() {
    let dir = tempfile::tempdir().unwrap();
    let card = repo("config/planing-card.toml");
    camloop_ok(&["planing", "--job", &card, "--out", "p.mpf"], dir.path());
    let text = std::fs::read_to_string(dir.path().join("p.mpf")).unwrap();
    assert!(
        text.contains("IF R50>=5 GOTOF SKIP_4") && text.contains("; arc 6 of 6"),
        "{text}"
    );
    camloop_ok(
        &[
            "planing",
            "--pitch-radius-mm",
            "40",
            "--z-peak-mm",
            "0",
            "--z-valley-mm",
            "-3",
            "--ratio-deg-per-mm",
            "0.75",
            "--x-start-mm",
            "0",
            "--x-end-mm",
            "80",
            "--z-clear-mm",
            "5",
            "--dialect",
            "iso",
            "--save-job",
            "mine.toml",
            "--out",
            "a.ngc",
        ],
        dir.path(),
    );
    let saved = dir.path().join("mine.toml");
    camloop_ok(
        &[
            "planing",
            "--job",
            saved.to_str().unwrap(),
            "--out",
            "b.ngc",
        ],
        dir.path(),
    );
    let (a, b) = (
        std::fs::read_to_string(dir.path().join("a.ngc")).unwrap(),
        std::fs::read_to_string(dir.path().join("b.ngc")).unwrap(),
    );
    assert!(a.contains("o500 if [#5000 LT 1]"), "{a}");
    assert_eq!(a, b, "the saved card holds every parameter of the run");
    let out = camloop(
        &["planing", "--x-start-mm", "0", "--out", "c.mpf"],
        dir.path(),
    );
    assert!(stderr(&out).contains("--pitch-radius-mm is required without --job"));
    assert!(!dir.path().join("c.mpf").exists());
}
