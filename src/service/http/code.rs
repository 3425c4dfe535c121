//! The API's error codes: one enum, each code with its HTTP status. The text of a code is
//! what clients and tests read (`{"code": "lobe_not_found", …}`), so a variant's text never
//! changes once released; strum writes it from the variant's name.

use axum::http::StatusCode;

/// Every stable code an API error carries. The wire text is the variant in snake case.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    strum::IntoStaticStr,
    strum::Display,
    strum::EnumIter,
    serde::Serialize,
    utoipa::ToSchema,
)]
#[strum(serialize_all = "snake_case")]
#[serde(rename_all = "snake_case")]
pub enum ApiCode {
    // Access and transport.
    Unauthorized,
    Forbidden,
    CsrfMismatch,
    LockedOut,
    /// Too many password checks waiting for a core: try again in a moment.
    SigninBusy,
    HostNotAllowed,
    /// The path exists, not with this method (405, with `Allow`).
    MethodNotAllowed,
    RouteWithoutRole,
    BodyTimeout,
    // What the client sent.
    InvalidBody,
    InvalidQuery,
    InvalidPath,
    InvalidName,
    InvalidRange,
    InvalidReason,
    InvalidVersion,
    InvalidVersions,
    InvalidWheelRadius,
    InvalidInfeed,
    InvalidWindow,
    // What the client asked for and is not there.
    MachineNotFound,
    LobeNotFound,
    FeatureNotFound,
    EventNotFound,
    MeasurementNotFound,
    TableVersionNotFound,
    NoParentVersion,
    NoData,
    // Where the machine runs.
    MachineStopped,
    MachineElsewhere,
    ClusterUnavailable,
    // A write the machine's loop refused or could not carry out.
    RollbackRefused,
    FreezeRefused,
    DressingRefused,
    CommandFailed,
    /// The machine's journal could not keep a write (disk full, folder unwritable).
    JournalUnavailable,
    /// The share's state folder (manifest, kept texts) could not be written.
    ShareStateFailed,
    // The history store (the codes of `StoreError`).
    StoreUnavailable,
    StoreCorrupt,
    StoreFull,
    StoreBusy,
    NotFound,
    Conflict,
    Invalid,
    MigrationFailed,
    StoreFailed,
    // The service itself.
    ProgramUnreadable,
    RandomFailed,
    Internal,
}

impl ApiCode {
    /// The code's text on the wire.
    pub fn as_str(self) -> &'static str {
        self.into()
    }

    /// The HTTP status an error with this code answers with. Only the extractors' rejections
    /// (`invalid_body`, `invalid_query`, `invalid_path`) may answer with axum's own status
    /// instead (415, 422, 413, …), since axum knows better what was wrong with the request.
    pub fn status(self) -> StatusCode {
        use ApiCode::*;
        match self {
            Unauthorized => StatusCode::UNAUTHORIZED,
            Forbidden | CsrfMismatch => StatusCode::FORBIDDEN,
            LockedOut => StatusCode::TOO_MANY_REQUESTS,
            HostNotAllowed => StatusCode::MISDIRECTED_REQUEST,
            MethodNotAllowed => StatusCode::METHOD_NOT_ALLOWED,
            BodyTimeout => StatusCode::REQUEST_TIMEOUT,
            InvalidBody | InvalidQuery | InvalidPath | InvalidName | InvalidRange
            | InvalidReason | InvalidVersion | InvalidVersions | InvalidWheelRadius
            | InvalidInfeed | InvalidWindow | Invalid => StatusCode::BAD_REQUEST,
            MachineNotFound | LobeNotFound | FeatureNotFound | EventNotFound
            | MeasurementNotFound | TableVersionNotFound | NoParentVersion | NoData | NotFound => {
                StatusCode::NOT_FOUND
            }
            RollbackRefused | FreezeRefused | DressingRefused | Conflict => StatusCode::CONFLICT,
            // Try again later, or once an operator acted (the code says which).
            MachineStopped | MachineElsewhere | ClusterUnavailable | StoreUnavailable
            | StoreCorrupt | StoreFull | StoreBusy | JournalUnavailable | SigninBusy => {
                StatusCode::SERVICE_UNAVAILABLE
            }
            RouteWithoutRole | CommandFailed | ShareStateFailed | MigrationFailed | StoreFailed
            | ProgramUnreadable | RandomFailed | Internal => StatusCode::INTERNAL_SERVER_ERROR,
        }
    }
}

impl From<&crate::store::StoreError> for ApiCode {
    fn from(e: &crate::store::StoreError) -> Self {
        use crate::store::StoreError;
        match e {
            StoreError::Unavailable { .. } => ApiCode::StoreUnavailable,
            StoreError::Corrupt { .. } => ApiCode::StoreCorrupt,
            StoreError::Full { .. } => ApiCode::StoreFull,
            StoreError::Busy { .. } => ApiCode::StoreBusy,
            StoreError::NotFound { .. } => ApiCode::NotFound,
            StoreError::Conflict { .. } => ApiCode::Conflict,
            StoreError::Invalid { .. } => ApiCode::Invalid,
            StoreError::Migration { .. } => ApiCode::MigrationFailed,
            StoreError::Backend { .. } => ApiCode::StoreFailed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use strum::IntoEnumIterator;

    #[test]
    fn codes_keep_their_wire_text() {
        // The texts clients read: a renamed variant must not change them.
        let texts: Vec<&str> = ApiCode::iter().map(ApiCode::as_str).collect();
        for expected in [
            "unauthorized",
            "csrf_mismatch",
            "host_not_allowed",
            "signin_busy",
            "route_without_role",
            "invalid_wheel_radius",
            "table_version_not_found",
            "machine_elsewhere",
            "rollback_refused",
            "command_failed",
            "journal_unavailable",
            "share_state_failed",
            "store_unavailable",
            "migration_failed",
            "random_failed",
        ] {
            assert!(texts.contains(&expected), "{expected} missing: {texts:?}");
        }
        assert_eq!(
            ApiCode::InvalidWheelRadius.to_string(),
            "invalid_wheel_radius"
        );
        let json = serde_json::to_string(&ApiCode::NoParentVersion).unwrap_or_default();
        assert_eq!(json, "\"no_parent_version\"");
    }

    /// Each case of a command's error answers with the code and status the API has always
    /// given it; a refusal takes the command's own code.
    #[test]
    fn a_commands_error_answers_with_its_code_and_status() {
        use crate::service::http::command_code;
        use camloop_loop::{CommandError, TableVersion};
        let reason = String::from("x");
        let cases = [
            (
                CommandError::VersionNotFound {
                    lobe: "x".parse().unwrap(),
                    version: TableVersion::new(3).unwrap(),
                },
                Some(ApiCode::TableVersionNotFound),
                404,
            ),
            (
                CommandError::StoreUnavailable {
                    reason: reason.clone(),
                },
                Some(ApiCode::StoreUnavailable),
                503,
            ),
            (
                CommandError::Refused {
                    reason: reason.clone(),
                },
                None,
                409,
            ),
            (
                CommandError::JournalUnavailable {
                    reason: reason.clone(),
                },
                Some(ApiCode::JournalUnavailable),
                503,
            ),
            (
                CommandError::ShareStateFailed {
                    reason: reason.clone(),
                },
                Some(ApiCode::ShareStateFailed),
                500,
            ),
            (
                CommandError::Elsewhere {
                    reason: reason.clone(),
                },
                Some(ApiCode::MachineElsewhere),
                503,
            ),
            (
                CommandError::Failed { reason },
                Some(ApiCode::CommandFailed),
                500,
            ),
        ];
        for refused in [
            ApiCode::RollbackRefused,
            ApiCode::FreezeRefused,
            ApiCode::DressingRefused,
        ] {
            for (e, code, status) in &cases {
                let got = command_code(e, refused);
                assert_eq!(got, code.unwrap_or(refused), "{e:?}");
                assert_eq!(got.status().as_u16(), *status, "{e:?}");
            }
        }
    }

    #[test]
    fn store_errors_keep_their_codes() {
        use crate::store::StoreError;
        let errors = [
            StoreError::Busy {
                target: "db".into(),
                reason: "waited 5 ms".into(),
            },
            StoreError::NotFound { what: "x".into() },
            StoreError::Invalid {
                field: "x",
                reason: "y".into(),
            },
        ];
        for e in errors {
            assert_eq!(ApiCode::from(&e).as_str(), e.code());
        }
    }
}
