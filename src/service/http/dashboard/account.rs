//! The pages around access: the sign-in form and the audit trail. Plain HTML with no inline
//! script, like every page.

use super::pages::{esc, when};
use crate::store::AuditRow;
use std::fmt::Write as _;

fn shell(title: &str, body: &str) -> String {
    format!(
        r#"<!doctype html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>{t} · camloop</title><link rel="icon" href="/assets/icon.svg" type="image/svg+xml"><link rel="stylesheet" href="/assets/app.css"><script src="/assets/app.js" defer></script></head>
<body><header><nav aria-label="breadcrumb"><a href="/">camloop</a> › {t}</nav><p id="who"></p></header>
<main><h1>{t}</h1>{body}</main>
<p id="notice" role="alert" hidden></p></body></html>
"#,
        t = esc(title),
    )
}

/// The sign-in form; `nonce` is the double-submit value, `next` where to go after.
pub(crate) fn signin_html(nonce: &str, next: &str, message: &str) -> String {
    let message = match message {
        "" => String::new(),
        m => format!(
            r#"<p id="signin-result" class="refused" role="alert">{}</p>"#,
            esc(m)
        ),
    };
    let body = format!(
        r#"{message}<form id="signin" method="post" action="/signin">
<input type="hidden" name="csrf" value="{n}"><input type="hidden" name="next" value="{x}">
<p><label for="name">User</label> <input id="name" name="name" autocomplete="username" required maxlength="32"></p>
<p><label for="password">Password</label> <input id="password" name="password" type="password" autocomplete="current-password" required></p>
<p><button type="submit">Sign in</button></p></form>
<p class="hint">Five failed attempts in 15 minutes lock the user and this address for 15 minutes.</p>"#,
        n = esc(nonce),
        x = esc(next),
    );
    shell("Sign in", &body)
}

/// The newest audit rows, newest first.
pub(crate) fn audit_html(rows: &[AuditRow]) -> String {
    let mut t = String::from(
        r#"<table id="audit"><caption>Who did what, newest first (chained: <code>camloop audit verify</code> checks it)</caption><thead><tr><th scope="col">#</th><th scope="col">Time (UTC)</th><th scope="col">User</th><th scope="col">Role</th><th scope="col">Client</th><th scope="col">Action</th><th scope="col">Target</th><th scope="col">Before → after</th><th scope="col">Result</th><th scope="col">Reason</th></tr></thead><tbody>"#,
    );
    for r in rows {
        let e = &r.entry;
        let target = [
            e.machine.clone(),
            e.feature.clone(),
            e.version.map(|v| format!("v{v}")),
        ]
        .into_iter()
        .flatten()
        .collect::<Vec<_>>()
        .join(" ");
        let change = match (&e.before, &e.after) {
            (None, None) => String::new(),
            (b, a) => format!(
                "{} → {}",
                b.as_deref().unwrap_or("–"),
                a.as_deref().unwrap_or("–")
            ),
        };
        let _ = write!(
            t,
            r#"<tr data-id="{}" class="{}"><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>"#,
            r.id,
            e.result.as_str(),
            r.id,
            when(e.at_ms),
            esc(&e.actor),
            e.role.as_str(),
            esc(&e.client),
            esc(&e.action),
            esc(&target),
            esc(&change),
            e.result.as_str(),
            esc(&e.reason),
        );
    }
    t.push_str("</tbody></table>");
    shell("Audit trail", &t)
}
