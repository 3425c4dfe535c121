//! Part recipes: the shipped ones parse, and a bad one is refused with every problem named.

use camloop::recipe::{Recipe, ShaftKind};
use std::path::Path;

#[test]
fn every_shipped_recipe_parses_and_its_lift_files_exist() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts");
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let recipe =
            Recipe::parse(&text, &path.display().to_string()).unwrap_or_else(|e| panic!("{e}"));
        for lobe in &recipe.lobes {
            assert!(
                lobe.lift_path(&path).exists(),
                "{}: {} missing",
                path.display(),
                lobe.lift.display()
            );
        }
        count += 1;
    }
    assert!(count >= 1, "no recipe in {}", dir.display());
}

#[test]
fn demo_recipe_has_the_documented_values() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
    let recipe = Recipe::parse(&std::fs::read_to_string(&path).unwrap(), "demo").unwrap();
    assert_eq!(recipe.kind, ShaftKind::Camshaft);
    assert_eq!(recipe.wheel.radius_mm, 250.0);
    let lobe = recipe.lobe("IN1").unwrap();
    assert_eq!(lobe.base_radius_mm, 20.0);
    assert_eq!(lobe.tolerance.len(), 1);
    // Eight lobes, two table numbers each.
    assert_eq!(recipe.lobes.len(), 8);
    assert_eq!(recipe.table.table_numbers, (1, 16));
    let ex4 = recipe.feature_setup(&path, "EX4").unwrap();
    assert_eq!(ex4.table_pair, (15, 16));
    assert_eq!(ex4.program.name, "DEMO_CAM_EX4");
    assert_eq!((ex4.index, ex4.phase_deg, ex4.z_mm), (8, 70.0, 320.0));
    assert_eq!(recipe.learning.gain, 0.8);
    // The speed plan's keys: off, with the removal limit that makes 30 rpm the fastest
    // constant speed of the intake lobes.
    assert!(!recipe.speed_plan.enabled);
    assert_eq!(recipe.speed_plan.q_w_max_mm3_mm_s, 2.36);
    assert_eq!(recipe.axis_limits.c_max_speed_rpm, 120.0);
    assert_eq!(recipe.axis_limits.c_max_accel_deg_s2, 3600.0);
}

/// A camshaft recipe of one flat-follower lobe L1 on a 250 mm wheel, with `sections` (TOML
/// tables) between the wheel and the lobe.
fn one_lobe_recipe(sections: &str) -> String {
    format!(
        "name = \"X\"\nkind = \"camshaft\"\n[wheel]\nradius_mm = 250\n{sections}[[lobes]]\n\
         name = \"L1\"\nlift = \"a.csv\"\nfollower = \"flat\"\nbase_radius_mm = 20\n"
    )
}

#[test]
fn an_enabled_speed_plan_with_a_bad_limit_is_named() {
    let text =
        one_lobe_recipe("[axis_limits]\nc_max_accel_deg_s2 = 0\n[speed_plan]\nenabled = true\n");
    let e = Recipe::parse(&text, "bad.toml").unwrap_err().to_string();
    assert!(e.contains("speed_plan (with axis_limits)"), "{e}");
    assert!(e.contains("c_max_accel_deg_s2 = 0"), "{e}");
}

/// C's table over the virtual axis is written rising: with C reversed in the program the
/// plan is refused, saying where to reverse it instead.
#[test]
fn an_enabled_speed_plan_with_c_reversed_is_refused() {
    let text = one_lobe_recipe(
        "[table]\ntable_numbers = [1, 4]\n[program]\nc_direction = -1\n[speed_plan]\nenabled = true\n",
    );
    let e = Recipe::parse(&text, "reversed.toml")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("speed_plan: enabled with program.c_direction = -1"),
        "{e}"
    );
    let forward = text.replace("c_direction = -1", "c_direction = 1");
    assert!(Recipe::parse(&forward, "forward.toml").is_ok());
}

/// With the plan on, each feature needs a second pair for C's table, after every X pair:
/// the demo's [1, 16] holds its 8 lobes' X pairs only.
#[test]
fn the_speed_plan_needs_a_c_pair_per_feature_after_the_x_pairs() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-camshaft.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let on = text.replace("enabled = false", "enabled = true");
    assert_ne!(on, text, "the demo recipe has `enabled = false`");
    let e = Recipe::parse(&on, "demo.toml").unwrap_err().to_string();
    assert!(
        e.contains("8 features need 32 table numbers (an X and a C pair each"),
        "{e}"
    );
    let wide = on.replace("table_numbers = [1, 16]", "table_numbers = [1, 32]");
    let recipe = Recipe::parse(&wide, "demo.toml").unwrap();
    let setups = recipe.feature_setups(&path).unwrap();
    let mut used = Vec::new();
    for s in &setups {
        let (c0, c1) = s.c_table_pair.expect("the plan is on");
        used.extend([s.table_pair.0, s.table_pair.1, c0, c1]);
    }
    assert_eq!(setups[0].table_pair, (1, 2));
    assert_eq!(setups[0].c_table_pair, Some((17, 18)));
    assert_eq!(setups[7].c_table_pair, Some((31, 32)));
    used.sort_unstable();
    assert_eq!(used, (1..=32).collect::<Vec<u32>>(), "every number once");
    // Off, no C pair, and the X pairs are where they were.
    let off = Recipe::parse(&text, "demo.toml").unwrap();
    let setups = off.feature_setups(&path).unwrap();
    assert!(setups.iter().all(|s| s.c_table_pair.is_none()));
    assert_eq!(setups[7].table_pair, (15, 16));
}

/// With the plan in camloop's whole cycle each feature needs a third pair, for X over VA
/// (X over C stays in use for the stages at constant speed): after every C pair, and the
/// range check counts it.
#[test]
fn the_plan_in_the_whole_cycle_needs_a_third_pair_per_feature() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config/parts/demo-camshaft-in-process-plan.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let narrow = text.replace("table_numbers = [1, 48]", "table_numbers = [1, 32]");
    assert_ne!(
        narrow, text,
        "the plan recipe has `table_numbers = [1, 48]`"
    );
    let e = Recipe::parse(&narrow, "plan.toml").unwrap_err().to_string();
    assert!(
        e.contains(
            "8 features need 48 table numbers (an X pair over C, a C and an X pair over VA each"
        ),
        "{e}"
    );
    let recipe = Recipe::parse(&text, "plan.toml").unwrap();
    let setups = recipe.feature_setups(&path).unwrap();
    let mut used = Vec::new();
    for s in &setups {
        assert!(s.plan_in_whole_cycle(), "{}", s.label);
        let (c0, c1) = s.c_table_pair.unwrap();
        let (v0, v1) = s.plan_x_table_pair.unwrap();
        used.extend([s.table_pair.0, s.table_pair.1, c0, c1, v0, v1]);
    }
    assert_eq!(setups[0].plan_x_table_pair, Some((33, 34)));
    assert_eq!(setups[7].plan_x_table_pair, Some((47, 48)));
    used.sort_unstable();
    assert_eq!(used, (1..=48).collect::<Vec<u32>>(), "every number once");
    // A table-only cycle with the plan keeps two pairs: the machine builder's cycle calls
    // one table program.
    let table_only = narrow.replace("program = \"whole\"", "program = \"table-only\"");
    let recipe = Recipe::parse(&table_only, "plan.toml").unwrap();
    let setups = recipe.feature_setups(&path).unwrap();
    assert!(setups.iter().all(|s| s.plan_x_table_pair.is_none()));
}

#[test]
fn a_bad_recipe_lists_every_problem() {
    let text = r#"
name = "X"
kind = "camshaft"
[wheel]
radius_mm = -1
[table]
points = 10
table_numbers = [3, 3]
[learning]
gain = 1.5
[[lobes]]
name = "L1"
lift = "a.csv"
follower = "roller"
base_radius_mm = 20
"#;
    let e = Recipe::parse(text, "bad.toml").unwrap_err().to_string();
    for expected in [
        "bad.toml: ",
        "wheel.radius_mm = -1",
        "table.points = 10",
        "table.table_numbers",
        "learning.gain = 1.5",
        "lobes.L1: roller follower needs roller_radius_mm",
    ] {
        assert!(e.contains(expected), "`{expected}` missing from `{e}`");
    }
}

/// A lobe's or pin's name keys folders, URLs and database rows: it is checked as the recipe
/// is read, and the message names the file, the line and the character at fault.
#[test]
fn a_feature_name_off_the_rule_is_refused_with_its_line() {
    let lobe = one_lobe_recipe("").replace("name = \"L1\"", "name = \"L 1\"");
    let e = Recipe::parse(&lobe, "bad.toml").unwrap_err().to_string();
    assert_eq!(
        e,
        "bad.toml: line 6: name `L 1` has ` ` at character 2: \
         only letters, digits, '-' or '_' are allowed"
    );
    let pin = "name = \"X\"\nkind = \"crankshaft\"\n[wheel]\nradius_mm = 250\n\
               [[pins]]\nname = \"../P1\"\nthrow_mm = 40\npin_radius_mm = 25\n";
    let e = Recipe::parse(pin, "crank.toml").unwrap_err().to_string();
    assert!(
        e.starts_with("crank.toml: line 6: name `../P1` has `.` at character 1"),
        "{e}"
    );
    // The same text with a plain name is a sound recipe.
    assert!(Recipe::parse(&pin.replace("../P1", "P1"), "crank.toml").is_ok());
}

#[test]
fn unknown_keys_are_errors() {
    let text = "name = \"X\"\nkind = \"camshaft\"\ncolour = \"red\"\n[wheel]\nradius_mm = 250\n";
    let e = Recipe::parse(text, "bad.toml").unwrap_err().to_string();
    assert!(
        e.starts_with("bad.toml: line 3: unknown field `colour`"),
        "{e}"
    );
}

/// The part name reaches the API's JSON, DFQ K1001/K1002 and the NC comment: it is held to
/// the machine-name rule at load, so no sink needs its own escaping.
#[test]
fn a_part_name_outside_the_plain_rule_is_refused_naming_the_file() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let good = "name = \"DEMO-CAM\"";
    assert!(text.contains(good));
    for bad in [
        "<script>alert(1)</script>",
        "CAM)\\nM30",
        "K1002 x",
        "a;b",
        "",
        "DRAWING-NUMBER-FAR-TOO-LONG-1234567",
    ] {
        let forged = text.replacen(good, &format!("name = \"{bad}\""), 1);
        let e = Recipe::parse(&forged, "evil.toml").unwrap_err().to_string();
        assert!(
            e.starts_with("evil.toml: ") && e.contains("must be 1–32 letters, digits, '-' or '_'"),
            "{bad}: {e}"
        );
    }
}
