//! The API's error (`{code, message}` with a status), axum's extractors wrapped so their
//! rejections keep that shape, and the name checks. Who may call what is `access.rs`,
//! which runs before any handler reads a byte of the body.

use super::AppState;
pub use super::access::Authorized;
pub use super::code::ApiCode;
use crate::names::{FeatureName, MachineName};
use axum::Json;
use axum::extract::{FromRequest, FromRequestParts, Path, Query, RawPathParams, Request};
use axum::http::StatusCode;
use axum::http::request::Parts;
use axum::response::{IntoResponse, Response};
use serde::Serialize;

/// Largest request body read, bytes: the writes take a few dozen.
const BODY_LIMIT: usize = 64 * 1024;

/// An API error: a stable code, the HTTP status it answers with (the code's own, see
/// [`ApiCode::status`]), and a message for people.
#[derive(Debug)]
pub struct ApiError {
    status: StatusCode,
    code: ApiCode,
    message: String,
    /// Seconds a client should wait before trying again (`Retry-After`), for a refusal
    /// that passes with time (busy, locked out).
    retry_after_s: Option<u64>,
}

impl ApiError {
    pub fn new(code: ApiCode, message: String) -> Self {
        ApiError {
            status: code.status(),
            code,
            message,
            retry_after_s: None,
        }
    }

    /// The same error with `Retry-After: seconds`.
    pub(crate) fn retry_after(mut self, seconds: u64) -> Self {
        self.retry_after_s = Some(seconds.max(1));
        self
    }

    /// An extractor's rejection: axum's status (415, 422, 413, …) with the API's code.
    pub(super) fn rejected(status: StatusCode, code: ApiCode, message: String) -> Self {
        ApiError {
            status,
            code,
            message,
            retry_after_s: None,
        }
    }

    pub fn code(&self) -> ApiCode {
        self.code
    }

    pub fn status(&self) -> StatusCode {
        self.status
    }

    pub fn message(&self) -> &str {
        &self.message
    }
}

/// The body of every error reply.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub(crate) struct ErrorBody<'a> {
    code: ApiCode,
    message: &'a str,
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = ErrorBody {
            code: self.code,
            message: &self.message,
        };
        let mut r = (self.status, Json(body)).into_response();
        if let Some(s) = self.retry_after_s {
            r.headers_mut()
                .insert(axum::http::header::RETRY_AFTER, s.into());
        }
        // For the access layer, which audits refused writes by their code.
        r.extensions_mut().insert(self.code);
        r
    }
}

impl From<crate::store::StoreError> for ApiError {
    fn from(e: crate::store::StoreError) -> Self {
        // Display never carries SQL text or credentials (see StoreError).
        ApiError::new(ApiCode::from(&e), e.to_string())
    }
}

/// A machine name from a path or query, by the one rule ([`MachineName`]).
pub fn machine_name(name: &str) -> Result<MachineName, ApiError> {
    MachineName::new(name).map_err(|e| ApiError::new(ApiCode::InvalidName, format!("machine: {e}")))
}

/// A lobe or pin name from a path or query: the same rule as machine names.
pub(crate) fn feature_name(name: &str) -> Result<FeatureName, ApiError> {
    FeatureName::new(name).map_err(|e| ApiError::new(ApiCode::InvalidName, format!("lobe: {e}")))
}

/// The first name among a request's path or query parameters that fails the rule, as the
/// API's `invalid_name` error. The typed extractors refuse such a request already (names
/// deserialise as [`MachineName`] and [`FeatureName`]); this says which name, and why,
/// with the code clients match on, rather than a generic path or query error.
fn name_refusal<'a>(params: impl IntoIterator<Item = (&'a str, &'a str)>) -> Option<ApiError> {
    params.into_iter().find_map(|(key, value)| match key {
        "machine" => machine_name(value).err(),
        "lobe" | "feature" => feature_name(value).err(),
        _ => None,
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
            .map_err(|r| ApiError::rejected(r.status(), ApiCode::InvalidBody, clip(&r.body_text())))
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
            ApiError::new(
                ApiCode::BodyTimeout,
                format!(
                    "the request body did not arrive within {} ms",
                    timeout.as_millis()
                ),
            )
        })?
        .map_err(|e| {
            ApiError::rejected(
                StatusCode::PAYLOAD_TOO_LARGE,
                ApiCode::InvalidBody,
                format!("request body unreadable or over {BODY_LIMIT} bytes: {e}"),
            )
        })
}

/// axum's query extractor, its rejections as the API's `{code, message}` errors.
pub struct ApiQuery<T>(pub T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned> FromRequestParts<S> for ApiQuery<T> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ApiError> {
        match Query::<T>::from_request_parts(parts, state).await {
            Ok(Query(v)) => Ok(ApiQuery(v)),
            Err(r) => {
                let pairs = Query::<Vec<(String, String)>>::try_from_uri(&parts.uri)
                    .map(|Query(pairs)| pairs)
                    .unwrap_or_default();
                let named = pairs.iter().map(|(k, v)| (k.as_str(), v.as_str()));
                Err(name_refusal(named).unwrap_or_else(|| {
                    ApiError::rejected(r.status(), ApiCode::InvalidQuery, clip(&r.body_text()))
                }))
            }
        }
    }
}

/// axum's path extractor, its rejections as the API's `{code, message}` errors.
pub struct ApiPath<T>(pub T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned + Send> FromRequestParts<S> for ApiPath<T> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ApiError> {
        match Path::<T>::from_request_parts(parts, state).await {
            Ok(Path(v)) => Ok(ApiPath(v)),
            Err(r) => {
                let raw = RawPathParams::from_request_parts(parts, state).await.ok();
                let named = raw.iter().flat_map(|p| p.iter());
                Err(name_refusal(named).unwrap_or_else(|| {
                    ApiError::rejected(r.status(), ApiCode::InvalidPath, clip(&r.body_text()))
                }))
            }
        }
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
