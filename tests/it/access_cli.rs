//! `camloop user`, `camloop token` and `camloop audit` on a real store: users with argon2id
//! hashes and the 12-character rule, tokens shown once and kept as digests, the audit trail
//! printed and verified. An audit row edited (or removed) directly in the database, past the
//! append-only triggers, is found by `camloop audit verify`, on SQLite and on PostgreSQL.

use crate::cli_support;
use crate::store_support;

use camloop::auth::token_digest;
use camloop::store::{RawPool, Store};
use std::io::Write as _;
use std::process::{Command, Output, Stdio};

/// Runs `camloop args… --database url` with `stdin` as standard input.
fn camloop(args: &[&str], url: &str, stdin: &str) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_camloop"))
        .args(args)
        .args(["--database", url])
        .env("USER", "tester")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the camloop binary runs");
    child
        .stdin
        .take()
        .unwrap()
        .write_all(stdin.as_bytes())
        .unwrap();
    child.wait_with_output().unwrap()
}

fn out(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn err(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Users and a token through the commands; returns the token.
async fn users_and_tokens(url: &str, store: &Store) -> String {
    let short = camloop(
        &["user", "add", "ann", "--role", "operator"],
        url,
        "eleven-char\n",
    );
    assert!(!short.status.success());
    assert!(err(&short).contains("at least 12"), "{}", err(&short));
    let add = camloop(
        &["user", "add", "ann", "--role", "operator"],
        url,
        "a-long-enough-secret\n",
    );
    assert!(add.status.success(), "{}", err(&add));
    let again = camloop(
        &["user", "add", "ann", "--role", "viewer"],
        url,
        "a-long-enough-secret\n",
    );
    assert!(!again.status.success(), "a second ann");
    let user = store.user("ann").await.unwrap().unwrap();
    assert!(
        user.password_hash.starts_with("$argon2id$"),
        "{}",
        user.password_hash
    );
    assert!(camloop::auth::verify_password(
        "a-long-enough-secret",
        &user.password_hash
    ));

    let above = camloop(
        &["token", "create", "--user", "ann", "--role", "engineer"],
        url,
        "",
    );
    assert!(!above.status.success(), "a token above its user's role");
    let create = camloop(
        &[
            "token",
            "create",
            "--user",
            "ann",
            "--role",
            "viewer",
            "--expires",
            "1d",
            "--label",
            "cell-7",
        ],
        url,
        "",
    );
    assert!(create.status.success(), "{}", err(&create));
    let token = out(&create).trim().to_string();
    assert!(token.starts_with("clt_") && token.len() == 68, "{token}");
    let grant = store
        .token_grant(&token_digest(&token))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(
        (grant.user.as_str(), grant.role.as_str()),
        ("ann", "viewer")
    );
    let day_ms = 86_400_000;
    let left = grant.expires_at_ms.as_millisecond() - camloop::clock::now().as_millisecond();
    assert!(left > day_ms - 60_000 && left <= day_ms, "{left}");
    let list = camloop(&["token", "list"], url, "");
    assert!(
        out(&list).contains("cell-7") && !out(&list).contains(&token),
        "{}",
        out(&list)
    );
    let revoke = camloop(&["token", "revoke", &grant.id.0.to_string()], url, "");
    assert!(revoke.status.success(), "{}", err(&revoke));
    assert!(
        store
            .token_grant(&token_digest(&token))
            .await
            .unwrap()
            .unwrap()
            .revoked_at_ms
            .is_some()
    );

    let passwd = camloop(&["user", "passwd", "ann"], url, "another-long-secret\n");
    assert!(passwd.status.success(), "{}", err(&passwd));
    let disable = camloop(&["user", "disable", "ann"], url, "");
    assert!(disable.status.success(), "{}", err(&disable));
    let list = out(&camloop(&["user", "list"], url, ""));
    assert!(
        list.lines()
            .any(|l| l.starts_with("ann") && l.contains("operator") && l.ends_with("disabled")),
        "{list}"
    );
    token
}

/// The trail as `camloop audit` prints it, and `verify` on the intact trail.
fn trail_reads_and_verifies(url: &str) {
    let audit = out(&camloop(&["audit", "--since", "1h"], url, ""));
    let actions: Vec<&str> = audit
        .lines()
        .filter_map(|l| l.split_whitespace().nth(6))
        .collect();
    assert_eq!(
        actions,
        [
            "user.add",
            "token.create",
            "token.revoke",
            "user.passwd",
            "user.disable"
        ],
        "{audit}"
    );
    assert!(
        audit
            .lines()
            .all(|l| l.contains("cli:tester (admin) from local")),
        "{audit}"
    );
    let verify = camloop(&["audit", "verify"], url, "");
    assert!(verify.status.success(), "{}", err(&verify));
    assert!(out(&verify).contains("intact: 5 rows"), "{}", out(&verify));
}

/// `verify` fails, naming `row` and why.
fn verify_names(url: &str, row: i64, why: &str) {
    let verify = camloop(&["audit", "verify"], url, "");
    assert!(!verify.status.success(), "verify passed a broken trail");
    let text = err(&verify);
    assert!(
        text.contains(&format!("row {row}: ")) && text.contains(why),
        "{text}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn users_tokens_and_a_row_edited_in_sqlite() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/camloop.db?mode=rwc", dir.path().display());
    let store = Store::connect(&url).await.unwrap();
    users_and_tokens(&url, &store).await;
    trail_reads_and_verifies(&url);
    let RawPool::Sqlite(pool) = store.raw_pool() else {
        unreachable!()
    };
    let edit = "UPDATE audit SET reason = 'nothing happened' WHERE id = 2";
    let refused = sqlx::query(edit).execute(pool).await;
    assert!(
        refused.unwrap_err().to_string().contains("append-only"),
        "the trigger refuses"
    );
    // Someone with the file drops the trigger and edits row 2.
    sqlx::query("DROP TRIGGER audit_no_update")
        .execute(pool)
        .await
        .unwrap();
    sqlx::query(edit).execute(pool).await.unwrap();
    verify_names(&url, 2, "content does not match");
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn users_tokens_and_rows_edited_and_removed_in_postgres() {
    let Some(pg) = store_support::postgres("users_tokens_and_rows_edited_in_postgres").await else {
        return;
    };
    let url = pg.server.as_ref().unwrap().url();
    users_and_tokens(&url, &pg.store).await;
    trail_reads_and_verifies(&url);
    let RawPool::Postgres(pool) = pg.store.raw_pool() else {
        unreachable!()
    };
    let edit = "UPDATE audit SET after_json = '{\"user\":\"mallory\"}' WHERE id = 2";
    let refused = sqlx::query(edit).execute(pool).await;
    assert!(
        refused.unwrap_err().to_string().contains("append-only"),
        "the trigger refuses"
    );
    sqlx::query("ALTER TABLE audit DISABLE TRIGGER audit_no_change")
        .execute(pool)
        .await
        .unwrap();
    sqlx::query(edit).execute(pool).await.unwrap();
    verify_names(&url, 2, "content does not match");
    // Removing a row in the middle breaks the next row's link.
    sqlx::query("DELETE FROM audit WHERE id = 4")
        .execute(pool)
        .await
        .unwrap();
    verify_names(&url, 5, "link to the row before");
}

/// The first start of the real binary makes `admin`: the password goes to a file only its
/// owner may read, its path is printed, and the password itself is nowhere in the output.
/// A second start leaves the file and the user as they are.
#[test]
fn the_first_start_writes_the_admin_password_to_an_owner_only_file_and_never_logs_it() {
    let dir = tempfile::tempdir().unwrap();
    let recipe = cli_support::repo("config/parts/demo-lobe.toml");
    let config = format!(
        "[database]\nurl = \"sqlite://var/camloop.db?mode=rwc\"\n[service]\nvar_dir = \"var\"\n[http]\nlisten = \"127.0.0.1:0\"\n\
         [[machines]]\nname = \"M7\"\nrecipe = \"{recipe}\"\nlobe = \"IN1\"\nshare = \"share/M7\"\n[machines.gauge]\nkind = \"sim\"\npart_interval_ms = 10\n"
    );
    std::fs::write(dir.path().join("camloop.toml"), config).unwrap();
    let run = || {
        cli_support::camloop(
            &["run", "--config", "camloop.toml", "--parts", "1"],
            dir.path(),
        )
    };
    let first = run();
    assert!(first.status.success(), "{}", err(&first));
    let file = dir.path().join("var/admin-password");
    let password = std::fs::read_to_string(&file).unwrap().trim().to_string();
    assert_eq!(password.chars().count(), 24);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&file).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
    }
    let output = format!("{}{}", out(&first), err(&first));
    assert!(
        output.contains("var/admin-password"),
        "the path is printed: {output}"
    );
    assert!(
        !output.contains(&password),
        "the password is never printed or logged"
    );
    let second = run();
    assert!(second.status.success(), "{}", err(&second));
    assert_eq!(std::fs::read_to_string(&file).unwrap().trim(), password);
    let users = cli_support::camloop(
        &["user", "list", "--database", "sqlite://var/camloop.db"],
        dir.path(),
    );
    let list = out(&users);
    assert_eq!(
        list.lines().filter(|l| l.starts_with("admin ")).count(),
        1,
        "{list}"
    );
}
