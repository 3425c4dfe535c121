//! `camloop user`, `camloop token` and `camloop audit`: users, their API tokens and the
//! audit trail, on the same store the service uses. Whoever runs these can open the
//! database, so they act as an admin; each change is audited as `cli:<login>`.

use super::history::{StoreArgs, connect, runtime};
use crate::audit_seal::AuditSeal;
use crate::auth::{UserName, hash_password, new_token, token_digest};
use crate::clock::now;
use crate::clock::parse_time;
use crate::store::{AuditEntry, AuditResult, HeadCheck, NewToken, Role, Store, TokenId};
use anyhow::{Context, bail};
use clap::{Args, Subcommand, ValueEnum};
use std::io::BufRead as _;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RoleArg {
    Viewer,
    Operator,
    Engineer,
    Admin,
}

impl From<RoleArg> for Role {
    fn from(r: RoleArg) -> Self {
        match r {
            RoleArg::Viewer => Role::Viewer,
            RoleArg::Operator => Role::Operator,
            RoleArg::Engineer => Role::Engineer,
            RoleArg::Admin => Role::Admin,
        }
    }
}

/// Where the store is (as `history`), accepted before or after the subcommand.
#[derive(Debug, Args)]
pub struct GlobalStoreArgs {
    /// Database URL (sqlite://… or postgres://…).
    #[arg(long, value_name = "URL", global = true)]
    pub database: Option<String>,
    /// Service configuration whose database to use.
    #[arg(
        long,
        value_name = "FILE",
        default_value = "config/camloop.toml",
        global = true
    )]
    pub config: std::path::PathBuf,
    /// The folder of the audit trail's key and head (`audit-key`, `audit-head`); default:
    /// where the configuration's service keeps them (beside the first admin's password),
    /// or `var` when the configuration cannot be read.
    #[arg(long, value_name = "DIR", global = true)]
    pub audit_dir: Option<std::path::PathBuf>,
}

impl GlobalStoreArgs {
    fn store(&self) -> StoreArgs {
        StoreArgs {
            database: self.database.clone(),
            config: self.config.clone(),
        }
    }

    /// Where the audit key and head are.
    fn seal_dir(&self) -> std::path::PathBuf {
        if let Some(dir) = &self.audit_dir {
            return dir.clone();
        }
        std::fs::read_to_string(&self.config)
            .ok()
            .and_then(|text| crate::config::Config::parse(&text, &self.config, |_| None).ok())
            .map_or_else(
                || std::path::PathBuf::from("var"),
                |c| crate::service::seal_dir(&c),
            )
    }

    /// The audit seal, its key made when there is none yet.
    fn seal(&self) -> anyhow::Result<AuditSeal> {
        Ok(AuditSeal::open_or_create(&self.seal_dir())?)
    }
}

#[derive(Debug, Args)]
pub struct UserArgs {
    #[command(subcommand)]
    pub action: UserAction,
    #[command(flatten)]
    pub store: GlobalStoreArgs,
}

#[derive(Debug, Subcommand)]
pub enum UserAction {
    /// Add a user; the password (at least 12 characters) is read from the first line of
    /// standard input.
    Add {
        name: String,
        #[arg(long, value_enum)]
        role: RoleArg,
    },
    /// Set a user's password, read from the first line of standard input. The user's
    /// dashboard sessions end at their next request; their tokens stay unless
    /// `--revoke-tokens`.
    Passwd {
        name: String,
        /// Also revoke every live token of the user (a password change after a leak).
        #[arg(long)]
        revoke_tokens: bool,
    },
    /// Disable a user: its sessions and tokens stop working (users are never deleted, so
    /// the audit trail keeps its names).
    Disable { name: String },
    /// Every user with role and state.
    List,
}

#[derive(Debug, Args)]
pub struct TokenArgs {
    #[command(subcommand)]
    pub action: TokenAction,
    #[command(flatten)]
    pub store: GlobalStoreArgs,
}

#[derive(Debug, Subcommand)]
pub enum TokenAction {
    /// Make an API token for a user; it is printed once and only its digest is kept.
    Create {
        /// The user the token acts as.
        #[arg(long)]
        user: String,
        /// The most the token may do (never more than its user's role).
        #[arg(long, value_enum)]
        role: RoleArg,
        /// Lifetime: `90d`, `12h` (at most 400 days).
        #[arg(long, default_value = "90d")]
        expires: String,
        /// What the token is for (a cell controller's name, a script).
        #[arg(long, default_value = "")]
        label: String,
    },
    /// Revoke a token by its id (see `token list`).
    Revoke { id: i64 },
    /// Every token (no secrets).
    List,
}

#[derive(Debug, Args)]
pub struct AuditArgs {
    #[command(subcommand)]
    pub action: Option<AuditAction>,
    /// From this time (see `history --since`); default: the last 24 hours.
    #[arg(long, value_name = "TIME")]
    pub since: Option<String>,
    #[command(flatten)]
    pub store: GlobalStoreArgs,
}

#[derive(Debug, Subcommand)]
pub enum AuditAction {
    /// Check every row's chain digest; fails (exit 1) naming the rows changed or removed.
    Verify,
}

/// `cli:<account>`: who ran the command, as the audit trail names them: the account of the
/// process's user id (not `$USER`, which whoever runs the command sets as they like), or
/// `uid<n>` when the system has no name for it.
fn cli_actor() -> String {
    let uid = nix::unistd::getuid();
    let login = nix::unistd::User::from_uid(uid)
        .ok()
        .flatten()
        .map_or_else(|| format!("uid{uid}"), |u| u.name);
    format!("cli:{}", login.chars().take(32).collect::<String>())
}

fn entry(action: &str, after: serde_json::Value, reason: String) -> AuditEntry {
    AuditEntry {
        at: now(),
        actor: cli_actor(),
        role: Role::Admin,
        client: "local".into(),
        action: action.into(),
        machine: None,
        feature: None,
        version: None,
        before: None,
        after: Some(after.to_string()),
        result: AuditResult::Ok,
        reason,
    }
}

fn read_password() -> anyhow::Result<String> {
    if std::io::IsTerminal::is_terminal(&std::io::stdin()) {
        eprintln!(
            "password (at least 12 characters, not easy to guess, not the user name; it shows as you type), then Enter:"
        );
    }
    let mut line = String::new();
    std::io::stdin()
        .lock()
        .read_line(&mut line)
        .context("cannot read the password from standard input")?;
    Ok(line.trim_end_matches(['\r', '\n']).to_string())
}

fn user_name(name: &str) -> anyhow::Result<UserName> {
    UserName::new(name).with_context(|| "user name")
}

pub(crate) fn run_user(args: UserArgs) -> anyhow::Result<()> {
    let password = match &args.action {
        UserAction::Add { name, .. } | UserAction::Passwd { name, .. } => {
            let p = read_password()?;
            crate::auth::check_new_password(&p, &user_name(name)?)?;
            Some(p)
        }
        _ => None,
    };
    let hash = password.map(|p| hash_password(&p)).transpose()?;
    runtime()?.block_on(async {
        let seal = args.store.seal()?;
        let store = connect(&args.store.store()).await?;
        let result = user(&store, &seal, args.action, hash.as_deref()).await;
        store.close().await;
        result
    })
}

async fn user(
    store: &Store,
    seal: &AuditSeal,
    action: UserAction,
    hash: Option<&str>,
) -> anyhow::Result<()> {
    let now = now();
    match action {
        UserAction::Add { name, role } => {
            let name = user_name(&name)?;
            let role = Role::from(role);
            store
                .add_user(name.as_str(), role, hash.unwrap_or_default(), now)
                .await?;
            let after = serde_json::json!({ "user": name, "role": role.as_str() });
            seal.append(store, &entry("user.add", after, String::new()))
                .await?;
            println!("user {name} added ({role})");
        }
        UserAction::Passwd {
            name,
            revoke_tokens,
        } => {
            let name = user_name(&name)?;
            if !store
                .set_password(name.as_str(), hash.unwrap_or_default(), now)
                .await?
            {
                bail!("no user {name}");
            }
            let after = serde_json::json!({ "user": name });
            seal.append(store, &entry("user.passwd", after, String::new()))
                .await?;
            println!(
                "password of {name} changed; its dashboard sessions end at their next request"
            );
            live_tokens_after_passwd(store, seal, &name, revoke_tokens).await?;
        }
        UserAction::Disable { name } => {
            let name = user_name(&name)?;
            if !store.disable_user(name.as_str(), now).await? {
                bail!("no enabled user {name}");
            }
            let after = serde_json::json!({ "user": name, "disabled": true });
            seal.append(store, &entry("user.disable", after, String::new()))
                .await?;
            println!("user {name} disabled");
        }
        UserAction::List => {
            println!("{:<32} {:<9} {:<20} state", "user", "role", "created (UTC)");
            for u in store.users().await? {
                let state = if u.disabled_at.is_some() {
                    "disabled"
                } else {
                    "enabled"
                };
                let created = crate::clock::utc_text(u.created_at);
                println!(
                    "{:<32} {:<9} {:<20} {state}",
                    u.name,
                    u.role.as_str(),
                    &created[..19]
                );
            }
        }
    }
    Ok(())
}

/// After a password change: revokes the user's live tokens when asked, else names them.
async fn live_tokens_after_passwd(
    store: &Store,
    seal: &AuditSeal,
    name: &UserName,
    revoke: bool,
) -> anyhow::Result<()> {
    let now = now();
    let live: Vec<_> = store
        .tokens()
        .await?
        .into_iter()
        .filter(|t| t.user == name.as_str() && t.revoked_at.is_none() && t.expires_at > now)
        .collect();
    if live.is_empty() {
        return Ok(());
    }
    if !revoke {
        let ids: Vec<String> = live.iter().map(|t| t.id.0.to_string()).collect();
        println!(
            "{name} has {} live tokens ({}): revoke them with --revoke-tokens, or one by one with `camloop token revoke ID`",
            live.len(),
            ids.join(", ")
        );
        return Ok(());
    }
    for t in live {
        if store.revoke_token(t.id, now).await? {
            let after = serde_json::json!({ "token": t.id.0, "user": name });
            seal.append(
                store,
                &entry("token.revoke", after, "password changed".into()),
            )
            .await?;
            println!("token {} revoked", t.id.0);
        }
    }
    Ok(())
}

/// A lifetime such as `90d` or `12h`; at most 400 days.
fn lifetime(text: &str) -> anyhow::Result<jiff::SignedDuration> {
    let t = text.trim();
    let (number, unit_h) = match t.char_indices().last() {
        Some((i, 'd')) => (&t[..i], 24),
        Some((i, 'h')) => (&t[..i], 1),
        _ => bail!("--expires `{text}`: give days or hours, like 90d or 12h"),
    };
    let n: i64 = number
        .parse()
        .ok()
        .filter(|n| *n > 0)
        .with_context(|| format!("--expires `{text}`: not a positive number"))?;
    let hours = n.saturating_mul(unit_h);
    if hours > 400 * 24 {
        bail!("--expires `{text}`: at most 400 days");
    }
    Ok(jiff::SignedDuration::from_hours(hours))
}

pub(crate) fn run_token(args: TokenArgs) -> anyhow::Result<()> {
    runtime()?.block_on(async {
        let seal = args.store.seal()?;
        let store = connect(&args.store.store()).await?;
        let result = token(&store, &seal, args.action).await;
        store.close().await;
        result
    })
}

async fn token(store: &Store, seal: &AuditSeal, action: TokenAction) -> anyhow::Result<()> {
    let now = now();
    match action {
        TokenAction::Create {
            user,
            role,
            expires,
            label,
        } => create_token(store, seal, &user, role.into(), &expires, &label).await?,
        TokenAction::Revoke { id } => {
            if !store.revoke_token(TokenId(id), now).await? {
                bail!("no live token {id}");
            }
            seal.append(
                store,
                &entry(
                    "token.revoke",
                    serde_json::json!({ "token": id }),
                    String::new(),
                ),
            )
            .await?;
            println!("token {id} revoked");
        }
        TokenAction::List => {
            println!(
                "{:>5} {:<32} {:<9} {:<20} {:<8} label",
                "id", "user", "role", "expires (UTC)", "state"
            );
            for t in store.tokens().await? {
                let state = match (t.revoked_at, t.expires_at <= now) {
                    (Some(_), _) => "revoked",
                    (None, true) => "expired",
                    (None, false) => "live",
                };
                let expires = crate::clock::utc_text(t.expires_at);
                println!(
                    "{:>5} {:<32} {:<9} {:<20} {:<8} {}",
                    t.id.0,
                    t.user,
                    t.role.as_str(),
                    &expires[..19],
                    state,
                    t.label
                );
            }
        }
    }
    Ok(())
}

/// `token create`: prints the token once; keeps its digest.
async fn create_token(
    store: &Store,
    seal: &AuditSeal,
    user: &str,
    role: Role,
    expires: &str,
    label: &str,
) -> anyhow::Result<()> {
    let now = now();
    let name = user_name(user)?;
    let Some(u) = store
        .user(name.as_str())
        .await?
        .filter(|u| u.disabled_at.is_none())
    else {
        bail!("no enabled user {name}");
    };
    if role > u.role {
        bail!(
            "a token of {name} can do at most what {name} can ({}), not {role}",
            u.role
        );
    }
    let secret = new_token()?;
    let expires_at = now + lifetime(expires)?;
    let label: String = label.chars().take(64).collect();
    let t = NewToken {
        user: u.id,
        label: label.clone(),
        sha256: token_digest(&secret),
        role,
        created_at: now,
        expires_at,
    };
    let id = store.add_token(&t).await?;
    let after = serde_json::json!({ "token": id.0, "user": name, "role": role.as_str(), "expires_at_ms": expires_at.as_millisecond(), "label": label });
    seal.append(store, &entry("token.create", after, String::new()))
        .await?;
    eprintln!(
        "token {} for {name} ({role}), valid until {} UTC; shown once, keep it secret:",
        id.0,
        crate::clock::utc_text(expires_at)
    );
    println!("{secret}");
    Ok(())
}

pub(crate) fn run_audit(args: AuditArgs) -> anyhow::Result<()> {
    let now = now();
    let since = match &args.since {
        Some(t) => parse_time(t, now)?,
        None => now - jiff::SignedDuration::from_hours(24),
    };
    runtime()?.block_on(async {
        let store = connect(&args.store.store()).await?;
        let result = match matches!(args.action, Some(AuditAction::Verify)) {
            true => verify_trail(&store, &args.store.seal_dir()).await,
            false => print_trail(&store, since).await,
        };
        store.close().await;
        result
    })
}

async fn verify_trail(store: &Store, seal_dir: &std::path::Path) -> anyhow::Result<()> {
    let seal = AuditSeal::open(seal_dir)?;
    let head = seal.as_ref().map(AuditSeal::head).transpose()?.flatten();
    let key = seal.as_ref().map(AuditSeal::key);
    let check = store.verify_audit(key, head.as_ref()).await?;
    for line in proof_lines(&check, seal_dir) {
        println!("{line}");
    }
    if check.intact() {
        println!("audit trail intact: {} rows, every link holds", check.rows);
        return Ok(());
    }
    for (id, why) in &check.broken {
        eprintln!("row {id}: {why}");
    }
    if let HeadCheck::Broken(why) = &check.head {
        eprintln!("head: {why}");
    }
    bail!(
        "audit trail broken: {} of {} rows{}",
        check.broken.len(),
        check.rows,
        match &check.head {
            HeadCheck::Broken(_) => ", and it no longer holds its signed head",
            _ => "",
        }
    )
}

/// What `verify` could prove and what not, one line each.
fn proof_lines(check: &crate::store::AuditCheck, seal_dir: &std::path::Path) -> Vec<String> {
    let unkeyed = check.rows - check.keyed_rows;
    let mut lines = Vec::new();
    match check.key_checked {
        true => lines.push(format!(
            "{} keyed rows checked with {}: not changed, inserted or re-chained without the key",
            check.keyed_rows,
            seal_dir.join(crate::audit_seal::KEY_FILE).display()
        )),
        false => lines.push(format!(
            "no key in {}: {} keyed rows checked for their links only",
            seal_dir.display(),
            check.keyed_rows
        )),
    }
    if unkeyed > 0 {
        lines.push(format!(
            "{unkeyed} rows from before the key: anyone who could write the database could have rewritten them"
        ));
    }
    lines.push(match &check.head {
        HeadCheck::NotGiven => {
            "no signed head: rows removed from the end would not be seen".to_string()
        }
        HeadCheck::Holds => {
            "the signed head holds: no row removed from the end since it was written".to_string()
        }
        HeadCheck::Broken(_) => "the signed head does not hold".to_string(),
    });
    lines.push(
        "not provable here: rows forged by someone who can read the key (the service's account)"
            .to_string(),
    );
    lines
}

async fn print_trail(store: &Store, since: jiff::Timestamp) -> anyhow::Result<()> {
    let mut after = 0;
    loop {
        let rows = store
            .audit(since, after, crate::store::MAX_AUDIT_PAGE, false)
            .await?;
        let Some(last) = rows.last() else {
            return Ok(());
        };
        after = last.id;
        for r in &rows {
            let e = &r.entry;
            let t = crate::clock::utc_text(e.at);
            let target = [
                e.machine.clone(),
                e.feature.clone(),
                e.version.map(|v| format!("v{v}")),
            ]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>()
            .join(" ");
            println!(
                "{:>6} {} {} ({}) from {} {} {} {} {}{}{}",
                r.id,
                &t[..19],
                e.actor,
                e.role.as_str(),
                e.client,
                e.action,
                if target.is_empty() { "-" } else { &target },
                e.result.as_str(),
                e.reason,
                e.before
                    .as_deref()
                    .map(|b| format!(" before {b}"))
                    .unwrap_or_default(),
                e.after
                    .as_deref()
                    .map(|a| format!(" after {a}"))
                    .unwrap_or_default(),
            );
        }
    }
}
