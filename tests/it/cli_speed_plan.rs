//! `camloop speed-plan` as a user runs it: real binary, the demo lobe, the figures it prints
//! and the chart it writes.

use crate::cli_support;

use cli_support::{camloop, camloop_ok, flat_cam_args, refusal, repo};

#[test]
fn the_demo_intake_lobe_plan_prints_the_time_saved_and_what_binds() {
    let dir = tempfile::tempdir().unwrap();
    let lift = repo("config/parts/demo-intake-lobe.csv");
    let out = camloop_ok(
        &flat_cam_args(
            "speed-plan",
            &lift,
            &["--svg", "plan.svg", "--program", "PLAN.SPF"],
        ),
        dir.path(),
    );
    let text = String::from_utf8(out.stdout).unwrap();
    // The demo's defaults make the fastest constant speed the demo's 30 rpm (to 0.1 rpm).
    assert!(text.contains("fastest constant C speed: 30.0"), "{text}");
    let saved: f64 = text
        .split(" % shorter")
        .next()
        .and_then(|s| s.rsplit('(').next())
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or_else(|| panic!("no time saved in: {text}"));
    assert!(saved >= 25.0, "{saved} % in: {text}");
    assert!(text.contains("removal rate Q'w"), "{text}");
    assert!(text.contains("C acceleration"), "{text}");
    let svg = std::fs::read_to_string(dir.path().join("plan.svg")).unwrap();
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    // One path per limit, the speed, the constant speed and the 100 % line.
    assert_eq!(svg.matches("<path ").count(), 9, "{svg}");
    let program = std::fs::read_to_string(dir.path().join("PLAN.SPF")).unwrap();
    assert!(program.starts_with("%_N_CAMLOOP_PLAN_SPF"), "{program}");
    assert!(program.contains("CTABDEF(X,VA,1,1)") && program.contains("CTABDEF(C,VA,2,2)"));
}

#[test]
fn a_bad_limit_is_named_on_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = camloop(
        &[
            "speed-plan",
            "crankpin",
            "--throw",
            "45",
            "--pin-radius",
            "27",
            "--wheel-radius",
            "300",
            "--q-w-max",
            "0",
        ],
        dir.path(),
    );
    let err = refusal(&out);
    assert!(err.contains("q_w_max_mm3_mm_s = 0"), "{err}");
}
