//! Both migration folders hold the same versions, and the binary embeds exactly those.

use std::collections::BTreeSet;
use std::path::Path;

fn versions(backend: &str) -> BTreeSet<(i64, String)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("crates/store/migrations")
        .join(backend);
    std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|name| name.ends_with(".sql"))
        .map(|name| {
            let (version, rest) = name.split_once('_').expect("NNNN_description.sql");
            let description = rest.trim_end_matches(".sql").to_owned();
            (version.parse().expect("numeric version"), description)
        })
        .collect()
}

fn tables(sql: &str) -> BTreeSet<String> {
    sql.lines()
        .filter_map(|l| l.trim().strip_prefix("CREATE TABLE "))
        .map(|rest| rest.split_whitespace().next().unwrap().to_owned())
        .collect()
}

/// (table, column) of each `ALTER TABLE t ADD COLUMN c …` line.
fn added_columns(sql: &str) -> BTreeSet<(String, String)> {
    sql.lines()
        .filter_map(|l| l.trim().strip_prefix("ALTER TABLE "))
        .filter_map(|rest| {
            let (table, column) = rest.split_once(" ADD COLUMN ")?;
            let column = column.split_whitespace().next()?;
            Some((table.trim().to_owned(), column.to_owned()))
        })
        .collect()
}

#[test]
fn both_backends_list_the_same_versions_and_the_binary_embeds_them() {
    let sqlite = versions("sqlite");
    let postgres = versions("postgres");
    assert!(!sqlite.is_empty());
    assert_eq!(sqlite, postgres);
    for (migrator, folder) in [
        (&camloop::store::SQLITE_MIGRATOR, &sqlite),
        (&camloop::store::POSTGRES_MIGRATOR, &postgres),
    ] {
        // sqlx writes a file name's underscores as spaces in the description.
        let embedded: BTreeSet<(i64, String)> = migrator
            .iter()
            .map(|m| (m.version, m.description.replace(' ', "_")))
            .collect();
        assert_eq!(&embedded, folder);
    }
}

#[test]
fn both_backends_create_the_same_tables() {
    let mut all = BTreeSet::new();
    let sqlite = camloop::store::SQLITE_MIGRATOR.iter();
    for (s, p) in sqlite.zip(camloop::store::POSTGRES_MIGRATOR.iter()) {
        assert_eq!(s.version, p.version);
        let t = tables(&s.sql);
        let columns = added_columns(&s.sql);
        assert!(
            !(t.is_empty() && columns.is_empty()),
            "migration {} creates no table and adds no column",
            s.version
        );
        assert_eq!(t, tables(&p.sql), "migration {}", s.version);
        assert_eq!(columns, added_columns(&p.sql), "migration {}", s.version);
        all.extend(t);
    }
    for table in ["measurements", "table_versions", "store_identity"] {
        assert!(all.contains(table), "{table} missing from {all:?}");
    }
    let infeed = camloop::store::SQLITE_MIGRATOR
        .iter()
        .find(|m| m.description == "dressing infeed")
        .unwrap();
    assert!(
        added_columns(&infeed.sql).contains(&("dressings".to_owned(), "infeed_um".to_owned())),
        "the dresser's infeed column"
    );
}
