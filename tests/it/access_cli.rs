//! `camloop user`, `camloop token` and `camloop audit` on a real store: users with argon2id
//! hashes and the 12-character rule, tokens shown once and kept as digests, the audit trail
//! printed and verified. An audit row edited (or removed) directly in the database, past the
//! append-only triggers, is found by `camloop audit verify`, on SQLite and on PostgreSQL.

use crate::cli_support;
use crate::store_support;

use camloop::auth::token_digest;
use camloop::store::{RawPool, Store};
use std::io::Write as _;
use std::path::Path;
use std::process::{Command, Output, Stdio};

/// A store and the folder of its audit key and head.
#[derive(Debug, Clone, Copy)]
struct At<'a> {
    url: &'a str,
    audit_dir: &'a Path,
}

/// Runs `camloop args… --database url --audit-dir dir` with `stdin` as standard input.
fn camloop(args: &[&str], at: At, stdin: &str) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_camloop"))
        .args(args)
        .args(["--database", at.url])
        .arg("--audit-dir")
        .arg(at.audit_dir)
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
async fn users_and_tokens(at: At<'_>, store: &Store) -> String {
    let short = camloop(
        &["user", "add", "ann", "--role", "operator"],
        at,
        "eleven-char\n",
    );
    assert!(!short.status.success());
    assert!(err(&short).contains("at least 12"), "{}", err(&short));
    // The policy: not blank, not the user name, not easy to guess; each says why.
    for (password, why) in [
        ("            \n", "only white space"),
        ("ann-ann-ann-ann\n", "contains, the user name `ann`"),
        (
            "passwordpassword\n",
            "too easy to guess (strength 0 of 4, at least 3 needed)",
        ),
    ] {
        let weak = camloop(&["user", "add", "ann", "--role", "admin"], at, password);
        assert!(!weak.status.success(), "{password:?} accepted");
        assert!(err(&weak).contains(why), "{password:?}: {}", err(&weak));
    }
    let add = camloop(
        &["user", "add", "ann", "--role", "operator"],
        at,
        "a-long-enough-secret\n",
    );
    assert!(add.status.success(), "{}", err(&add));
    let again = camloop(
        &["user", "add", "ann", "--role", "viewer"],
        at,
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
        at,
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
        at,
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
    let left = grant.expires_at.as_millisecond() - camloop::clock::now().as_millisecond();
    assert!(left > day_ms - 60_000 && left <= day_ms, "{left}");
    let list = camloop(&["token", "list"], at, "");
    assert!(
        out(&list).contains("cell-7") && !out(&list).contains(&token),
        "{}",
        out(&list)
    );
    let revoke = camloop(&["token", "revoke", &grant.id.0.to_string()], at, "");
    assert!(revoke.status.success(), "{}", err(&revoke));
    assert!(
        store
            .token_grant(&token_digest(&token))
            .await
            .unwrap()
            .unwrap()
            .revoked_at
            .is_some()
    );

    let passwd = camloop(&["user", "passwd", "ann"], at, "another-long-secret\n");
    assert!(passwd.status.success(), "{}", err(&passwd));
    let disable = camloop(&["user", "disable", "ann"], at, "");
    assert!(disable.status.success(), "{}", err(&disable));
    let list = out(&camloop(&["user", "list"], at, ""));
    assert!(
        list.lines()
            .any(|l| l.starts_with("ann") && l.contains("operator") && l.ends_with("disabled")),
        "{list}"
    );
    token
}

/// The trail as `camloop audit` prints it, and `verify` on the intact trail.
fn trail_reads_and_verifies(at: At<'_>) {
    let audit = out(&camloop(&["audit", "--since", "1h"], at, ""));
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
    // The actor is the account running the command (as `id -un` names it), not the
    // `USER=tester` the command ran with.
    let id = Command::new("id").arg("-un").output().unwrap();
    let account = String::from_utf8_lossy(&id.stdout).trim().to_string();
    assert_ne!(account, "tester");
    let actor = format!("cli:{account} (admin) from local");
    assert!(
        audit.lines().all(|l| l.contains(&actor)),
        "{actor}: {audit}"
    );
    let verify = camloop(&["audit", "verify"], at, "");
    assert!(verify.status.success(), "{}", err(&verify));
    assert!(out(&verify).contains("intact: 5 rows"), "{}", out(&verify));
}

/// `verify` fails, naming `row` and why.
fn verify_names(at: At<'_>, row: i64, why: &str) {
    let verify = camloop(&["audit", "verify"], at, "");
    assert!(!verify.status.success(), "verify passed a broken trail");
    let text = err(&verify);
    assert!(
        text.contains(&format!("row {row}: ")) && text.contains(why),
        "{text}"
    );
}

/// Runs `sql` on `pool`, expecting it refused with `why`.
macro_rules! refused {
    ($pool:expr, $sql:expr, $why:expr) => {{
        let e = sqlx::query($sql)
            .execute($pool)
            .await
            .unwrap_err()
            .to_string();
        assert!(e.contains($why), "{}: {e}", $sql);
    }};
}

/// Runs `sql` on `pool`: the forger got past the triggers.
macro_rules! forge {
    ($pool:expr, $sql:expr) => {
        sqlx::query($sql).execute($pool).await.unwrap()
    };
}

/// `verify` fails and says the signed head no longer holds.
fn verify_finds_the_head_broken(at: At<'_>) {
    let verify = camloop(&["audit", "verify"], at, "");
    assert!(!verify.status.success(), "verify passed a shortened trail");
    assert!(err(&verify).contains("no longer holds"), "{}", err(&verify));
}

/// A copy of row 5 appended as row 6, linked to row 5: a forged row after the last one.
const APPEND_FORGED: &str = "INSERT INTO audit (id, at_ms, actor, role, client, action, result, reason, prev_sha256, row_sha256) \
     SELECT 6, at_ms, 'mallory', role, client, action, result, reason, row_sha256, row_sha256 FROM audit WHERE id = 5";

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn users_tokens_and_a_trail_forged_in_sqlite() {
    let dir = tempfile::tempdir().unwrap();
    let url = format!("sqlite://{}/camloop.db?mode=rwc", dir.path().display());
    let at = At {
        url: &url,
        audit_dir: dir.path(),
    };
    let store = Store::connect(&url).await.unwrap();
    users_and_tokens(at, &store).await;
    trail_reads_and_verifies(at);
    let RawPool::Sqlite(pool) = store.raw_pool() else {
        unreachable!()
    };
    let edit = "UPDATE audit SET reason = 'nothing happened' WHERE id = 2";
    refused!(pool, edit, "append-only");
    // INSERT OR REPLACE deletes the row it replaces without firing the DELETE trigger.
    let replace = "INSERT OR REPLACE INTO audit (id, at_ms, actor, role, client, action, result, reason, prev_sha256, row_sha256, chain) \
         SELECT id, at_ms, 'mallory', role, client, action, result, reason, prev_sha256, row_sha256, chain FROM audit WHERE id = 5";
    refused!(pool, replace, "only the next id");
    refused!(
        pool,
        APPEND_FORGED.replace("SELECT 6", "SELECT 9").as_str(),
        "only the next id"
    );
    // Someone with the file drops the triggers.
    for t in ["audit_no_update", "audit_no_delete", "audit_next_id"] {
        forge!(pool, &format!("DROP TRIGGER {t}"));
    }
    forge!(pool, APPEND_FORGED);
    verify_names(at, 6, "unkeyed row after keyed ones");
    forge!(pool, "DELETE FROM audit WHERE id = 6");
    // The newest row removed: every link still holds; the head does not.
    forge!(pool, "DELETE FROM audit WHERE id = 5");
    verify_finds_the_head_broken(at);
    // Renumbered: the key covers the id.
    forge!(pool, "UPDATE audit SET id = id + 10");
    verify_names(at, 11, "keyed digest does not match");
    forge!(pool, "UPDATE audit SET id = id - 10");
    forge!(pool, edit);
    verify_names(at, 2, "keyed digest does not match");
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn users_tokens_and_a_trail_forged_in_postgres() {
    let Some(pg) = store_support::postgres("users_tokens_and_a_trail_forged_in_postgres").await
    else {
        return;
    };
    let server = pg.server.as_ref().unwrap();
    let url = server.url();
    let at = At {
        url: &url,
        audit_dir: pg.dir.path(),
    };
    users_and_tokens(at, &pg.store).await;
    trail_reads_and_verifies(at);
    let RawPool::Postgres(pool) = pg.store.raw_pool() else {
        unreachable!()
    };
    let edit = "UPDATE audit SET after_json = '{\"user\":\"mallory\"}' WHERE id = 2";
    refused!(pool, edit, "append-only");
    refused!(pool, "TRUNCATE audit", "append-only");
    refused!(pool, "DELETE FROM audit WHERE id = 5", "append-only");
    refused!(
        pool,
        APPEND_FORGED
            .replace(") SELECT", ") OVERRIDING SYSTEM VALUE SELECT")
            .replace("SELECT 6", "SELECT 9")
            .as_str(),
        "only the next id"
    );
    // The site's set-up: the tables belong to an owner; the service's role may read and
    // append to the trail and nothing more, so it can neither empty it nor drop a trigger.
    forge!(pool, "CREATE ROLE camloop_writer LOGIN");
    forge!(pool, "GRANT SELECT, INSERT ON audit TO camloop_writer");
    let writer_url = url.replace("postgres://postgres@", "postgres://camloop_writer@");
    let writer = sqlx::PgPool::connect(&writer_url).await.unwrap();
    refused!(&writer, "TRUNCATE audit", "permission denied");
    refused!(&writer, "DELETE FROM audit", "permission denied");
    refused!(
        &writer,
        "ALTER TABLE audit DISABLE TRIGGER audit_no_change",
        "must be owner"
    );
    writer.close().await;
    // The owner (or a superuser) gets past the triggers.
    for t in ["audit_no_change", "audit_next_id", "audit_no_truncate"] {
        forge!(pool, &format!("ALTER TABLE audit DISABLE TRIGGER {t}"));
    }
    forge!(
        pool,
        APPEND_FORGED
            .replace(") SELECT", ") OVERRIDING SYSTEM VALUE SELECT")
            .as_str()
    );
    verify_names(at, 6, "unkeyed row after keyed ones");
    forge!(pool, "DELETE FROM audit WHERE id >= 5");
    verify_finds_the_head_broken(at);
    forge!(pool, "TRUNCATE audit");
    verify_finds_the_head_broken(at);
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
