//! The API's error (`{code, message}` with a status), axum's extractors wrapped so their
//! rejections keep that shape, and the name checks. Who may call what is `access.rs`,
//! which runs before any handler reads a byte of the body.

use super::AppState;
pub use super::access::Authorized;
use crate::names::{MachineName, check_plain_name};
use axum::Json;
use axum::extract::{FromRequest, FromRequestParts, Path, Query, Request};
use axum::http::StatusCode;
use axum::http::request::Parts;
use axum::response::{IntoResponse, Response};
use serde::Serialize;

/// Largest request body read, bytes: the writes take a few dozen.
const BODY_LIMIT: usize = 64 * 1024;

/// An API error: HTTP status, stable code, message.
#[derive(Debug)]
pub struct ApiError(pub StatusCode, pub &'static str, pub String);

/// The body of every error reply.
#[derive(Debug, Serialize)]
struct ErrorBody<'a> {
    code: &'a str,
    message: &'a str,
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = ErrorBody {
            code: self.1,
            message: &self.2,
        };
        (self.0, Json(body)).into_response()
    }
}

impl From<crate::store::StoreError> for ApiError {
    fn from(e: crate::store::StoreError) -> Self {
        use crate::store::StoreError;
        let status = match e {
            StoreError::NotFound { .. } => StatusCode::NOT_FOUND,
            StoreError::Invalid { .. } => StatusCode::BAD_REQUEST,
            StoreError::Conflict { .. } => StatusCode::CONFLICT,
            // Readers beyond the store's bound wait, then get this: try again later.
            StoreError::Unavailable { .. } | StoreError::Busy { .. } => {
                StatusCode::SERVICE_UNAVAILABLE
            }
            // The database cannot serve until an operator acts (its code says why).
            StoreError::Corrupt { .. } | StoreError::Full { .. } => StatusCode::SERVICE_UNAVAILABLE,
            _ => StatusCode::INTERNAL_SERVER_ERROR,
        };
        // Display never carries SQL text or credentials (see StoreError).
        ApiError(status, e.code(), e.to_string())
    }
}

/// A machine name from a path or query, by the one rule ([`MachineName`]).
pub fn machine_name(name: &str) -> Result<MachineName, ApiError> {
    MachineName::new(name).map_err(|e| {
        ApiError(
            StatusCode::BAD_REQUEST,
            "invalid_name",
            format!("machine: {e}"),
        )
    })
}

/// A lobe or pin name from a path or query: the same rule as machine names.
pub(crate) fn feature_name(name: &str) -> Result<(), ApiError> {
    check_plain_name(name).map_err(|e| {
        ApiError(
            StatusCode::BAD_REQUEST,
            "invalid_name",
            format!("lobe: {e}"),
        )
    })
}

/// axum's JSON body extractor, its rejections as the API's `{code, message}` errors. The body
/// must arrive within the configured body timeout and be at most 64 KiB.
pub struct ApiJson<T>(pub T);

impl<T: serde::de::DeserializeOwned> FromRequest<AppState> for ApiJson<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, ApiError> {
        let (parts, body) = req.into_parts();
        let bytes = read_body(body, state.body_timeout).await?;
        let req = Request::from_parts(parts, axum::body::Body::from(bytes));
        Json::<T>::from_request(req, state)
            .await
            .map(|Json(v)| ApiJson(v))
            .map_err(|r| ApiError(r.status(), "invalid_body", clip(&r.body_text())))
    }
}

/// A request body, within `timeout` and at most 64 KiB.
pub(super) async fn read_body(
    body: axum::body::Body,
    timeout: std::time::Duration,
) -> Result<axum::body::Bytes, ApiError> {
    tokio::time::timeout(timeout, axum::body::to_bytes(body, BODY_LIMIT))
        .await
        .map_err(|_| {
            ApiError(
                StatusCode::REQUEST_TIMEOUT,
                "body_timeout",
                format!(
                    "the request body did not arrive within {} ms",
                    timeout.as_millis()
                ),
            )
        })?
        .map_err(|e| {
            ApiError(
                StatusCode::PAYLOAD_TOO_LARGE,
                "invalid_body",
                format!("request body unreadable or over {BODY_LIMIT} bytes: {e}"),
            )
        })
}

/// axum's query extractor, its rejections as the API's `{code, message}` errors.
pub struct ApiQuery<T>(pub T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned> FromRequestParts<S> for ApiQuery<T> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ApiError> {
        Query::<T>::from_request_parts(parts, state)
            .await
            .map(|Query(v)| ApiQuery(v))
            .map_err(|r| ApiError(r.status(), "invalid_query", clip(&r.body_text())))
    }
}

/// axum's path extractor, its rejections as the API's `{code, message}` errors.
pub struct ApiPath<T>(pub T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned + Send> FromRequestParts<S> for ApiPath<T> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ApiError> {
        Path::<T>::from_request_parts(parts, state)
            .await
            .map(|Path(v)| ApiPath(v))
            .map_err(|r| ApiError(r.status(), "invalid_path", clip(&r.body_text())))
    }
}

/// An extractor's rejection text as an error message may carry it: each `quoted` value
/// cut to [`crate::names::MAX_QUOTED_CHARS`] characters, and the whole to 256, so what a
/// client sent (a 10 kB path segment, a huge query) never comes back whole.
fn clip(text: &str) -> String {
    let mut out = String::new();
    for (i, piece) in text.split('`').enumerate() {
        if i > 0 {
            out.push('`');
        }
        // Odd pieces sit between backticks: values quoted from the request.
        match i % 2 {
            1 => out.push_str(&crate::names::quote(piece)),
            _ => out.push_str(piece),
        }
    }
    crate::names::quote_up_to(&out, 256)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejection_texts_quote_at_most_64_characters_of_the_request() {
        let sent = "9".repeat(10_000);
        let text = format!("Cannot parse `{sent}` to a `i64`");
        let clipped = clip(&text);
        assert_eq!(
            clipped,
            format!("Cannot parse `{}…` to a `i64`", "9".repeat(64))
        );
        let unquoted = clip(&format!("bad value {sent}"));
        assert!(unquoted.chars().count() <= 257, "{}", unquoted.len());
    }
}
