//! The pages around access: the sign-in form and the audit trail. Plain HTML with no inline
//! script, like every page.

use super::pages::{shell, when};
use crate::store::AuditRow;
use maud::{Markup, html};

/// A page with no live region: the breadcrumb ends at its title.
fn plain(title: &str, body: Markup) -> String {
    shell(
        title,
        html! { " › " (title) },
        html! { p id="who" {} },
        body,
    )
}

/// The sign-in form; `nonce` is the double-submit value, `next` where to go after.
pub(crate) fn signin_html(nonce: &str, next: &str, message: &str) -> String {
    let body = html! {
        @if !message.is_empty() {
            p id="signin-result" class="refused" role="alert" { (message) }
        }
        form id="signin" method="post" action="/signin" {
            input type="hidden" name="csrf" value=(nonce);
            input type="hidden" name="next" value=(next);
            p { label for="name" { "User" } " " input id="name" name="name" autocomplete="username" required maxlength="32"; }
            p { label for="password" { "Password" } " " input id="password" name="password" type="password" autocomplete="current-password" required; }
            p { button type="submit" { "Sign in" } }
        }
        p class="hint" { "Five failed attempts in 15 minutes lock the user and this address for 15 minutes." }
    };
    plain("Sign in", body)
}

/// One audit row: what it acted on and the change it made.
fn audit_row(r: &AuditRow) -> Markup {
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
    html! {
        tr data-id=(r.id) class=(e.result.as_str()) {
            td { (r.id) } td { (when(e.at)) } td { (e.actor) } td { (e.role.as_str()) }
            td { (e.client) } td { (e.action) } td { (target) } td { (change) }
            td { (e.result.as_str()) } td { (e.reason) }
        }
    }
}

/// The newest audit rows, newest first.
pub(crate) fn audit_html(rows: &[AuditRow]) -> String {
    let body = html! {
        table id="audit" {
            caption { "Who did what, newest first (chained: " code { "camloop audit verify" } " checks it)" }
            thead { tr {
                th scope="col" { "#" } th scope="col" { "Time (UTC)" } th scope="col" { "User" }
                th scope="col" { "Role" } th scope="col" { "Client" } th scope="col" { "Action" }
                th scope="col" { "Target" } th scope="col" { "Before → after" }
                th scope="col" { "Result" } th scope="col" { "Reason" }
            } }
            tbody { @for r in rows { (audit_row(r)) } }
        }
    };
    plain("Audit trail", body)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_a_request_brings_is_escaped_in_text_and_attributes() {
        let page = signin_html("n\"x", "/a?b=<c>&d", "<b>no</b> & 'then'");
        assert!(page.contains(r#"value="n&quot;x""#), "{page}");
        assert!(page.contains(r#"value="/a?b=&lt;c&gt;&amp;d""#), "{page}");
        assert!(
            page.contains("&lt;b&gt;no&lt;/b&gt; &amp; 'then'"),
            "{page}"
        );
        assert!(!page.contains("<b>"), "{page}");
        // The one script is the file the CSP allows; no inline script or style.
        assert_eq!(page.matches("<script").count(), 1, "{page}");
        assert!(page.contains(r#"<script src="/assets/app.js" defer></script>"#));
        assert!(!page.contains("style="), "{page}");
    }
}
