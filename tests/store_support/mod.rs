//! Test backends for the history store: a SQLite file in a tempdir, and a throwaway
//! PostgreSQL server started from the machine's own binaries.

#![allow(dead_code)]

pub mod data;
pub mod pg;

use camloop::names::{FeatureName, MachineName};
use camloop::store::Store;

/// A machine name for a store call, on one line (`&m("M1")`).
pub fn m(machine: &str) -> MachineName {
    machine.parse().expect("a plain machine name")
}

/// A feature (lobe or pin) name for a store call, on one line (`&f("in1")`).
pub fn f(feature: &str) -> FeatureName {
    feature.parse().expect("a plain feature name")
}

/// A table version for a store call, on one line (`tv(3)`).
pub fn tv(n: i64) -> camloop::core::ids::TableVersion {
    camloop::core::ids::TableVersion::from_i64(n).expect("a version is 1 or more")
}

/// A store and whatever keeps it alive (tempdir, server). Dropped in field order: the store
/// pool first, then the server.
pub struct TestStore {
    pub store: Store,
    pub server: Option<pg::TempPostgres>,
    pub dir: tempfile::TempDir,
}

pub async fn sqlite() -> TestStore {
    let dir = tempfile::tempdir().unwrap();
    // A parent folder that does not exist yet: connect must create it.
    let url = format!(
        "sqlite://{}?mode=rwc",
        dir.path().join("var").join("camloop.db").display()
    );
    let store = Store::connect(&url).await.unwrap();
    TestStore {
        store,
        server: None,
        dir,
    }
}

/// A fresh PostgreSQL database, or `None` (with a skip line) when the server binaries are
/// missing and `CAMLOOP_REQUIRE_POSTGRES` is not `1`.
pub async fn postgres(test: &str) -> Option<TestStore> {
    let server = pg::start_or_skip(test)?;
    let store = Store::connect(&server.url()).await.unwrap();
    Some(TestStore {
        store,
        server: Some(server),
        dir: tempfile::tempdir().unwrap(),
    })
}
