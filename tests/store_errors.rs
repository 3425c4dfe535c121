//! The history store when the database is down, misplaced or misnamed: clear
//! `StoreError`s with stable codes, no panic, no password in the message.

mod store_support;

use camloop::store::Store;
use store_support::data::measurement;

#[tokio::test]
async fn sqlite_reopens_with_its_data() {
    let t = store_support::sqlite().await;
    let id = t
        .store
        .insert_measurement(&measurement("M1", "in1", 1, 1))
        .await
        .unwrap();
    t.store.close().await;
    assert_eq!(
        t.store.machines().await.unwrap_err().code(),
        "store_unavailable",
        "a closed pool reports the store unavailable"
    );
    let url = format!("sqlite://{}", t.dir.path().join("var/camloop.db").display());
    let again = Store::connect(&url).await.unwrap();
    assert!(again.measurement(id).await.unwrap().is_some());
}

#[tokio::test]
async fn postgres_down_is_unavailable_without_the_password() {
    // A port that was free a moment ago and has no listener now.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let url = format!("postgres://camloop:s3cret@127.0.0.1:{port}/camloop");
    let e = Store::connect(&url).await.unwrap_err();
    assert_eq!(e.code(), "store_unavailable");
    assert_eq!(
        e.to_string(),
        format!("store unavailable at 127.0.0.1:{port}/camloop: connection refused")
    );
    assert!(!format!("{e:?}").contains("s3cret"));
}

#[tokio::test]
async fn sqlite_in_an_impossible_place_is_unavailable() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "not a folder").unwrap();
    let url = format!("sqlite://{}?mode=rwc", file.join("camloop.db").display());
    let e = Store::connect(&url).await.unwrap_err();
    assert_eq!(e.code(), "store_unavailable");
    assert!(e.to_string().contains("cannot create folder"), "{e}");
}

#[tokio::test]
async fn unknown_url_scheme_is_invalid() {
    let e = Store::connect("mysql://u:p@h/db").await.unwrap_err();
    assert_eq!(
        e.to_string(),
        "invalid database url: scheme `mysql` is not sqlite: or postgres://"
    );
}
