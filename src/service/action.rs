//! What a caller may ask of the service, each with the least role that may ask it: the one
//! vocabulary every adapter authorises by (each HTTP route names its action, each OPC UA
//! method too), so no adapter authorises by another's names (a URL, a node id).
//!
//! It lives in the service, not the loop crate, because roles are the store's (users and
//! the audit trail keep them); neither adapter owns it.

use crate::store::Role;

/// One kind of request, whatever adapter it came through.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Action {
    /// Reading: the history, tables and programs, the dashboards, metrics, the API
    /// description, the cluster's leases.
    Read,
    /// Acknowledging an alarm.
    Acknowledge,
    /// Reporting a wheel dressing (the tables are regenerated for the new radius).
    ReportDressing,
    /// Delivering a stored table version of one feature again.
    Rollback,
    /// Rolling several features of a part back together.
    RollbackPart,
    /// Freezing a feature's learning, or letting it learn again.
    FreezeLearning,
    /// Reading the audit trail.
    ReadAudit,
}

impl Action {
    /// Every action.
    pub const ALL: [Action; 7] = [
        Action::Read,
        Action::Acknowledge,
        Action::ReportDressing,
        Action::Rollback,
        Action::RollbackPart,
        Action::FreezeLearning,
        Action::ReadAudit,
    ];

    /// The least role that may ask for it: `viewer` reads; `operator` also acknowledges
    /// and reports dressings; `engineer` also rolls back, freezes learning and reads the
    /// audit trail.
    pub const fn role(self) -> Role {
        match self {
            Action::Read => Role::Viewer,
            Action::Acknowledge | Action::ReportDressing => Role::Operator,
            Action::Rollback | Action::RollbackPart | Action::FreezeLearning => Role::Engineer,
            Action::ReadAudit => Role::Engineer,
        }
    }

    /// Whether a caller with `role` (`None`: no role at all) may ask for it.
    pub fn allowed(self, role: Option<Role>) -> bool {
        role.is_some_and(|r| r >= self.role())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each role may do what the ones before it may; nobody without a role may do anything;
    /// an admin may do everything.
    #[test]
    fn roles_nest_and_admin_may_do_everything() {
        for action in Action::ALL {
            assert!(!action.allowed(None), "{action:?}");
            assert!(action.allowed(Some(Role::Admin)), "{action:?}");
            for (lower, higher) in Role::ALL.iter().zip(Role::ALL.iter().skip(1)) {
                if action.allowed(Some(*lower)) {
                    assert!(action.allowed(Some(*higher)), "{action:?} {lower} {higher}");
                }
            }
        }
        assert!(!Action::Rollback.allowed(Some(Role::Operator)));
        assert!(Action::Acknowledge.allowed(Some(Role::Operator)));
        assert!(!Action::Acknowledge.allowed(Some(Role::Viewer)));
    }
}
