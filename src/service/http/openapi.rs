//! The API description served at `/openapi.json` (OpenAPI 3.0).

use axum::Json;
use serde_json::{Value, json};

pub(super) async fn openapi() -> Json<Value> {
    let get = |summary: &str| json!({ "get": { "summary": summary, "responses": { "200": { "description": "OK" }, "4XX": { "description": "error: {code, message}" }, "503": { "description": "store unavailable" } } } });
    let write = |summary: &str, ok: &str, extra: Value| {
        let mut responses = json!({
            "200": { "description": ok },
            "401": { "description": "no caller, or a wrong, expired or revoked token (checked before the body is read)" },
            "403": { "description": "forbidden (the caller's role is below the route's) or csrf_mismatch (a session's write without X-CSRF-Token)" },
            "429": { "description": "locked_out: 5 failed attempts in 15 minutes from this user or address" },
            "404": { "description": "machine_not_found, lobe_not_found or table_version_not_found" },
            "408": { "description": "body_timeout" },
            "409": { "description": "refused" },
            "503": { "description": "machine_stopped or store_unavailable" }
        });
        if let (Some(r), Some(e)) = (responses.as_object_mut(), extra.as_object()) {
            r.extend(e.clone());
        }
        json!({ "summary": summary, "responses": responses })
    };
    Json(json!({
        "openapi": "3.0.3",
        "info": { "title": "camloop", "version": env!("CARGO_PKG_VERSION"), "description": "Every route needs a role (viewer reads; operator acknowledges and reports dressings; engineer rolls back and reads the audit trail; admin manages users): send Authorization: Bearer <token> (camloop token create). On a loopback listener anonymous callers read as viewer unless auth.anonymous_read = false." },
        "paths": {
            "/healthz": get("service and database health"),
            "/metrics": get("Prometheus metrics"),
            "/api/v1/cluster": get("with [cluster]: each machine's lease (owner, fencing epoch, live, run here); {enabled: false} without"),
            "/api/v1/machines": get("machines and their lobes or pins: configured ones and those in the history"),
            "/api/v1/machines/{machine}/measurements": get("measurement history of production parts, newest first; filters lobe, since_ms, until_ms, verdict, limit, cursor; masters=true lists the master runs (part ids MASTER…) instead"),
            "/api/v1/machines/{machine}/events": get("alarms and events, newest first"),
            "/api/v1/machines/{machine}/rollback": { "post": write("roll several features back together (a whole part); body {\"versions\": {\"IN1\": 5, \"EX1\": 7}}; every version is checked before any is pushed; role engineer", "delivered: {status, version: null, message}", json!({})) },
            "/api/v1/machines/{machine}/parts/{part}": get("one part (a shaft), feature by feature: its measurements and whether it passed"),
            "/api/v1/machines/{machine}/features/{feature}/capability": get("process capability of every characteristic of a feature (n, mean, σ within and overall, Cp/Cpk, Pp/Ppk with lower 95 % bounds, the fitted model, expected and observed share out of tolerance; no index without a recipe tolerance, and the note says so); window=parts:N (default parts:125) | since:TIME | dressing | recipe; chart=true adds the I-MR/EWMA chart with the run rules' flags; master runs are left out"),
            "/api/v1/machines/{machine}/lobes/{lobe}/tables": get("table versions, newest first"),
            "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/program": get("program text of a table version"),
            "/api/v1/machines/{machine}/lobes/{lobe}/tables/{version}/diff": get("X difference to the parent version at every table point, µm"),
            "/api/v1/measurements/{id}": get("one measurement with its averaged profile and analysis"),
            "/api/v1/machines/{machine}/lobes/{lobe}/learning": { "post": write("role engineer: freeze a feature's learning (the correction stays) or let it learn again; body {\"frozen\": true, \"reason\": \"…\"} or {\"frozen\": false}", "done: {status, version: null, message}", json!({})) },
            "/api/v1/audit": get("role engineer: the audit trail, newest first (who, role, client address, action, target, before/after, result, reason); since_ms, limit ≤ 1000"),
            "/api/v1/machines/{machine}/dressings": {
                "get": get("wheel dressings, newest first")["get"],
                "post": write("report a wheel dressing; body {\"wheel_radius_mm\": R, \"infeed_um\": D} (D, the dresser's measured infeed, optional); regenerates the table for the new radius; role operator", "recorded, table regenerated: {status, version, message}", json!({ "400": { "description": "implausible radius or infeed" } }))
            },
            "/api/v1/machines/{machine}/events/{id}/ack": { "post": write("acknowledge an event or alarm (the dashboard's button); role operator (Authorization: Bearer <token> or a dashboard session); a second acknowledgement changes nothing", "acknowledged: {status, version: null, message}", json!({ "404": { "description": "event_not_found" } })) },
            "/api/v1/machines/{machine}/lobes/{lobe}/rollback": { "post": write("deliver a stored version again; body {\"version\": N}; role engineer", "delivered: {status, version, message}", json!({})) },
        }
    }))
}
