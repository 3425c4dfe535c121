//! A machine loop in-process, without the service, for the tests that feed it measurements
//! directly: the demo lobe's setup, a simulated measurement of a part ground with its nominal
//! table, and the loop on a fresh SQLite store.

use camloop::core::measure::RawMeasurement;
use camloop::recipe::{FeatureSetup, Recipe};
use camloop::service::machine::{MachineLoop, MachinePaths, StoreHandle};
use camloop::service::metrics::Metrics;
use camloop::sim::{CommandedTable, GrinderConfig, PartLabels, SimGrinder, Workpiece};
use camloop::store::Store;
use std::path::Path;
use std::sync::Arc;

/// IN1 of `config/parts/demo-lobe.toml`.
pub fn demo_lobe_setup() -> FeatureSetup {
    let recipe_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/parts/demo-lobe.toml");
    let recipe = Recipe::load(&recipe_path).expect("shipped recipe");
    recipe.feature_setup(&recipe_path, "IN1").expect("its lobe")
}

/// A 360-point measurement of the cam `setup` ground with its nominal table on the default
/// simulated grinder (gauge noise `seed`), labelled `labels`, in the lobe's own frame.
pub fn nominal_measurement(setup: &FeatureSetup, labels: PartLabels, seed: u64) -> RawMeasurement {
    let camloop::core::compensate::Feature::Cam(g) = setup.feature else {
        panic!("a cam")
    };
    let mut sim = SimGrinder::new(GrinderConfig::default(), Workpiece::Cam(g), seed).unwrap();
    let geometry = setup.feature.part(&setup.nominal).unwrap();
    let table =
        CommandedTable::nominal(&geometry, 360, camloop::core::fit::TableForm::Poly).unwrap();
    let ground = sim.grind(&table).unwrap();
    sim.measure(&ground, &labels)
}

/// Machine `name` grinding `setups`, its store `db.sqlite` in `dir` with share and state
/// beside it.
pub async fn start_machine(
    dir: &Path,
    name: &str,
    setups: Vec<FeatureSetup>,
    metrics: Arc<Metrics>,
) -> MachineLoop {
    let url = format!("sqlite://{}/db.sqlite?mode=rwc", dir.display());
    let store: StoreHandle = Arc::new(tokio::sync::RwLock::new(Some(
        Store::connect(&url).await.unwrap(),
    )));
    let paths = MachinePaths {
        share_dir: dir.join("share"),
        state_dir: dir.join("state"),
    };
    MachineLoop::start(name.parse().unwrap(), setups, paths, store, metrics)
        .await
        .unwrap()
}
