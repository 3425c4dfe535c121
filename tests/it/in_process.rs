//! The shipped in-process configuration (`config/in-process-cell.toml`) and its recipe: the cycle
//! loads and passes its checks, a bad cycle is refused naming the key, the service refuses a
//! whole-cycle recipe on a gauge whose frames carry no stage, and the cell grinds as the manual says.

use camloop::core::compensate::TableRequest;
use camloop::core::cycle::limits::stage_load;
use camloop::core::speed_plan::ProfileSamples;
use camloop::recipe::Recipe;
use camloop::sim::cell::CellSetup;
use camloop::sim::cycle_cell::{self, CycleCellConfig, CycleCellSetup};
use std::path::Path;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn shipped() -> (CycleCellConfig, Recipe, std::path::PathBuf) {
    let path = root().join("config/in-process-cell.toml");
    let config: CycleCellConfig = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let recipe_path = root().join("config").join(&config.recipe);
    (config, Recipe::load(&recipe_path).unwrap(), recipe_path)
}

#[test]
fn the_shipped_cycle_loads_and_its_rough_stage_is_within_the_removal_limit() {
    let (config, recipe, path) = shipped();
    let setup = recipe.feature_setup(&path, &config.feature).unwrap();
    let cycle = setup.cycle.as_ref().expect("[cycle]");
    assert_eq!(cycle.stages.len(), 6);
    // The recipe's comment: Q'w 1.77 of 2.36 at 30 rpm for 0.015 mm/rev.
    let part = setup.feature.part(&setup.nominal).unwrap();
    let load = stage_load(&ProfileSamples::new(&part).unwrap(), 0.015, 30.0);
    assert!(
        (load.q_w_mm3_mm_s - 1.77).abs() < 0.01,
        "{}",
        load.q_w_mm3_mm_s
    );
}

fn with_cycle(edit: &dyn Fn(&str) -> String) -> Result<(), String> {
    let (_, _, path) = shipped();
    let text = edit(&std::fs::read_to_string(&path).unwrap());
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("r.toml");
    std::fs::write(&file, text).unwrap();
    std::fs::copy(
        root().join("config/parts/demo-intake-lobe.csv"),
        dir.path().join("demo-intake-lobe.csv"),
    )
    .unwrap();
    let recipe = Recipe::load(&file).map_err(|e| format!("{e:#}"))?;
    recipe
        .feature_setup(&file, "IN1")
        .map(|_| ())
        .map_err(|e| format!("{e:#}"))
}

#[test]
fn a_bad_cycle_is_refused_naming_the_key() {
    assert_eq!(with_cycle(&|t| t.to_owned()), Ok(()));
    let err = with_cycle(&|t| t.replace("stock_mm = 0.2 ", "stock_mm = 0.25 ")).unwrap_err();
    assert!(
        err.contains("cycle.stages: the infeeds add up to 0.2000 mm, cycle.stock_mm is 0.2500 mm"),
        "{err}"
    );
    // 0.03 mm/rev at 30 rpm takes off 3.54 mm³/(mm·s): over the recipe's 2.36 (the manual
    // quotes this message).
    let err = with_cycle(&|t| {
        t.replace("infeed_per_rev_mm = 0.015", "infeed_per_rev_mm = 0.03")
            .replace("revolutions = 10", "revolutions = 5")
    })
    .unwrap_err();
    assert!(
        err.contains("feature IN1: cycle.stages[0] (rough): Q'w 3.539 mm³/(mm·s) at C = 120.0° (0.03 mm/rev at 30 rpm) exceeds speed_plan.q_w_max_mm3_mm_s = 2.36"),
        "{err}"
    );
}

/// A whole cycle needs a gauge that tells the measurement before the finish from the
/// finished part's: CAN frames carry no stage, so such a machine is refused naming why; the
/// simulator (which hands its in-process measurements over as such) is accepted.
#[test]
fn the_service_refuses_a_whole_cycle_on_a_gauge_without_stages() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("camloop.toml");
    let recipe = root().join("config/parts/demo-lobe-in-process.toml");
    let config = |gauge: &str| {
        let text = format!(
            "[service]\nvar_dir = \"var\"\n[database]\nurl = \"sqlite://var/db.sqlite?mode=rwc\"\n[[machines]]\nname = \"M1\"\nrecipe = \"{}\"\nshare = \"share\"\n[machines.gauge]\n{gauge}\n",
            recipe.display()
        );
        std::fs::write(&path, &text).unwrap();
        camloop::config::Config::parse(&text, &path, |_| None).unwrap()
    };
    std::fs::write(dir.path().join("gauge.dbc"), "").unwrap();
    let err = camloop::config::check(config(
        "kind = \"can\"\ninterface = \"vcan0\"\ndbc = \"gauge.dbc\"",
    ))
    .unwrap_err();
    assert!(
        format!("{err:#}").contains(
            "its [cycle] program = \"whole\" needs a gauge that says which measurement is taken before the finish, and CAN and serial frames carry no stage"
        ),
        "{err:#}"
    );
    camloop::config::check(config("kind = \"sim\"")).unwrap();
}

#[test]
fn the_shipped_cell_grinds_the_first_part_right() {
    let (config, recipe, path) = shipped();
    let setup = recipe.feature_setup(&path, &config.feature).unwrap();
    let cell = CellSetup {
        nominal: setup.nominal.clone(),
        feature: setup.feature,
        request: TableRequest { ..setup.request },
        params: setup.params.clone(),
        limits: setup.limits.clone(),
        grinder: config.grinder.clone(),
        seed: config.seed,
        speed_plan: setup.speed_plan,
    };
    let run = cycle_cell::run(
        &CycleCellSetup {
            cell,
            cycle: setup.cycle.clone().unwrap(),
            measure_before_finish: config.measure_before_finish,
            answer_polls: config.answer_polls,
            station: Default::default(),
        },
        config.parts,
    )
    .unwrap();
    for p in &run {
        eprintln!(
            "part {:2}: {:.2} µm ({})",
            p.part, p.max_lift_error_um, p.in_process
        );
    }
    assert_eq!(run.len(), 12);
    assert!(run[0].max_lift_error_um <= 1.0, "{:?}", run[0]);
    assert!(run[2..].iter().all(|p| p.max_lift_error_um <= 0.5));
}

/// The controller contract through every stage: ten table versions delivered to a folder,
/// the whole-cycle program run once per version on one control, the handshake never
/// answered. Every grind of every run (approach, rough, semi-finish, spark-out, and after
/// the measurement the finish and spark-out) couples the version just delivered.
#[test]
fn every_stage_of_every_run_couples_the_newest_table() {
    use camloop::core::program::{
        CycleMachine, CycleStation, MainProgramSettings, ProgramSettings, READY_PROGRAM,
        next_table_number, render_cycle_program, render_g1_table, render_ready_program,
    };
    use camloop::core::table::TablePoint;
    let (_, recipe, _) = shipped();
    let cycle = recipe.cycle.clone().unwrap();
    let table = ProgramSettings {
        name: "DEMO_CAM_TABLE".into(),
        ..ProgramSettings::default()
    };
    let machine = CycleMachine {
        cycle: &cycle,
        c_speed_rpm: 30.0,
        wheel_radius_mm: 250.0,
        clear_x_mm: 13.0,
    };
    let stations = [CycleStation {
        table: &table,
        label: "IN1",
        z_mm: 0.0,
        plan: None,
    }];
    let main = render_cycle_program(&MainProgramSettings::default(), &machine, &stations).unwrap();
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join(format!("{READY_PROGRAM}.SPF")),
        render_ready_program(0),
    )
    .unwrap();
    let load = |name: &str| std::fs::read_to_string(dir.path().join(format!("{name}.SPF"))).ok();
    let mut control = camloop::sim::Control::new();
    control.enable_overlay();
    let mut number = 0;
    for version in 1..=10u32 {
        number = next_table_number(number, (1, 2));
        let points: Vec<TablePoint> = (0..36)
            .map(|i| {
                let c_deg = 10.0 * f64::from(i);
                let x_mm = 3.0 + 2.5 * c_deg.to_radians().cos() + 0.01 * f64::from(version);
                TablePoint {
                    c_deg,
                    d_mm: 250.0 + x_mm,
                    x_mm,
                }
            })
            .collect();
        let settings = ProgramSettings {
            table_number: number,
            ..table.clone()
        };
        std::fs::write(
            dir.path().join("DEMO_CAM_TABLE.SPF"),
            render_g1_table(&points, &settings).unwrap(),
        )
        .unwrap();
        let run = control.run_cycle(&main, &load).unwrap();
        // Approach, rough, semi-finish, spark-out; approach, finish, spark-out.
        assert_eq!(run.ground.len(), 7, "version {version}");
        for g in &run.ground {
            assert_eq!(g.table_number, number, "version {version}");
            let camloop::sim::TableShape::G1(p) = &g.shape else {
                panic!("a G1 table")
            };
            assert!((p[0].x_mm - (5.5 + 0.01 * f64::from(version))).abs() < 1e-9);
        }
    }
    assert_eq!(control.defined_tables(), [1, 2]);
}
