//! What `/healthz` says: the state each component of the service reports ("starting",
//! "ok", "degraded" with a reason), and the service's status drawn from them. A component
//! (the machines while they open, the loop's backlog, a link to a broker) sets its own entry;
//! the status is the worst of them, so a new component needs no change here.

use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::Duration;

/// One component's state; ordered from best to worst.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum State {
    Ok,
    /// Not yet serving its part (the machines are still opening).
    Starting,
    /// Serving, but not as it should (it cannot keep up, a link is down).
    Degraded,
}

/// One component as `/healthz` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct Component {
    pub name: String,
    pub state: State,
    /// Why it is not ok.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

/// The components' states, set by each component and read by `/healthz`.
#[derive(Debug, Default)]
pub struct HealthBoard {
    components: Mutex<BTreeMap<String, (State, Option<String>)>>,
}

impl HealthBoard {
    /// Sets component `name`'s state (`reason`: why it is not ok).
    pub fn set(&self, name: &str, state: State, reason: Option<String>) {
        self.components
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(name.to_string(), (state, reason));
    }

    /// Every component, in name order.
    pub fn components(&self) -> Vec<Component> {
        self.components
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .map(|(name, (state, reason))| Component {
                name: name.clone(),
                state: *state,
                reason: reason.clone(),
            })
            .collect()
    }
}

/// The service's status: the worst of its components' (ok with none).
pub fn status(components: &[Component]) -> State {
    components
        .iter()
        .map(|c| c.state)
        .max()
        .unwrap_or(State::Ok)
}

/// A measurement waiting this long to be recorded makes the loop "degraded": the issue's
/// goal is 2 s from received to durable, so 5 s is well past a slow part.
pub const LAG_DEGRADED: Duration = Duration::from_secs(5);

/// The loop's component from its backlog: degraded, with the figures, once the oldest
/// measurement waiting has waited [`LAG_DEGRADED`].
pub fn loop_component(lag: super::backlog::Lag) -> Component {
    let late = lag.oldest.filter(|age| *age >= LAG_DEGRADED);
    Component {
        name: "loop".into(),
        state: if late.is_some() {
            State::Degraded
        } else {
            State::Ok
        },
        reason: late.map(|age| {
            format!(
                "cannot keep up: {} measurements wait to be recorded, the oldest for {:.1} s",
                lag.waiting,
                age.as_secs_f64()
            )
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::backlog::Lag;

    #[test]
    fn the_status_is_the_worst_component_state() {
        let board = HealthBoard::default();
        assert_eq!(status(&board.components()), State::Ok);
        board.set("machines", State::Starting, Some("3 of 5 open".into()));
        board.set("mqtt", State::Ok, None);
        assert_eq!(status(&board.components()), State::Starting);
        board.set("mqtt", State::Degraded, Some("broker unreachable".into()));
        assert_eq!(status(&board.components()), State::Degraded);
        board.set("mqtt", State::Ok, None);
        board.set("machines", State::Ok, None);
        assert_eq!(status(&board.components()), State::Ok);
        assert_eq!(board.components().len(), 2);
    }

    #[test]
    fn the_loop_is_degraded_once_a_measurement_waits_past_the_limit() {
        let fresh = Lag {
            waiting: 40,
            oldest: Some(LAG_DEGRADED - Duration::from_millis(1)),
        };
        assert_eq!(loop_component(fresh).state, State::Ok);
        let late = Lag {
            waiting: 40,
            oldest: Some(LAG_DEGRADED),
        };
        let c = loop_component(late);
        assert_eq!(c.state, State::Degraded);
        assert_eq!(
            c.reason.as_deref(),
            Some("cannot keep up: 40 measurements wait to be recorded, the oldest for 5.0 s")
        );
        assert_eq!(loop_component(Lag::default()).state, State::Ok);
    }
}
