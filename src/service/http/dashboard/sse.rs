//! The live channel: every measurement the store holds is sent to the open dashboards as a
//! Server-Sent Event within [`POLL`] of being stored.
//!
//! One poller per server, running only while a dashboard listens, asks the store for its
//! newest measurement id every [`POLL`] (one index lookup) and broadcasts the new parts'
//! summaries. Polling the store rather than hooking the machine loop means a part is shown
//! exactly when it is in the database, whichever path put it there (the loop, a journal
//! replay after an outage), and the machine loop does not change. A browser that reconnects
//! sends `Last-Event-ID` and gets the parts it missed.

use crate::core::ids::PartId;
use crate::core::measure::is_master_part;
use crate::names::{FeatureName, MachineName};
use crate::service::machine::StoreHandle;
use crate::store::{MeasurementId, MeasurementSummary};
use axum::extract::State;
use axum::http::{HeaderMap, header};
use axum::response::{IntoResponse, Response};
use futures_util::stream;
use std::convert::Infallible;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::{broadcast, watch};

/// How often the store is asked for new parts.
pub(super) const POLL: Duration = Duration::from_millis(250);
/// A comment line this often keeps proxies and the browser from closing an idle stream.
const KEEP_ALIVE: Duration = Duration::from_secs(15);
/// Parts sent to a reconnecting browser at most (the page reloads its tables anyway).
const CATCH_UP: u32 = 200;

/// The server's shutdown signal, handed to every request by `serve`, so open event streams
/// end when the service stops instead of holding the shutdown for the drain time.
#[derive(Clone)]
pub struct Stopping(pub watch::Receiver<bool>);

/// One part as the dashboard's script receives it (`event: part`).
#[derive(Debug, Clone, serde::Serialize)]
pub(super) struct PartEvent {
    pub id: i64,
    pub machine: MachineName,
    pub lobe: FeatureName,
    pub part: PartId,
    pub received_at_ms: i64,
    pub verdict: &'static str,
    pub max_profile_error_um: f64,
    pub base_radius_error_um: f64,
    pub phase_error_deg: f64,
}

impl From<&MeasurementSummary> for PartEvent {
    fn from(m: &MeasurementSummary) -> Self {
        Self {
            id: m.id.0,
            machine: m.machine.clone(),
            lobe: m.lobe.clone(),
            part: m.part.clone(),
            received_at_ms: m.received_at.as_millisecond(),
            verdict: m.verdict.as_str(),
            max_profile_error_um: m.max_profile_error_um,
            base_radius_error_um: m.base_radius_error_um,
            phase_error_deg: m.phase_error_deg,
        }
    }
}

/// An event ready to send: its id and its `data:` line.
type Frame = (i64, Arc<str>);

/// The broadcast of new parts, started with the first listener, stopped after the last.
#[derive(Clone)]
pub(super) struct Live {
    store: StoreHandle,
    sender: Arc<Mutex<Option<broadcast::Sender<Frame>>>>,
}

impl Live {
    pub(super) fn new(store: StoreHandle) -> Self {
        Self {
            store,
            sender: Arc::default(),
        }
    }

    /// A receiver of new parts. A new poller starts from the newest id at this moment, so
    /// the page's refresh when its stream opens covers everything before.
    async fn subscribe(&self) -> broadcast::Receiver<Frame> {
        if let Some(tx) = self
            .sender
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .as_ref()
        {
            return tx.subscribe();
        }
        let store = self.store.read().await.clone();
        let newest = match store {
            Some(s) => s.newest_measurement_id().await.ok().flatten(),
            None => None,
        };
        let mut slot = self.sender.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(tx) = slot.as_ref() {
            return tx.subscribe();
        }
        let (tx, rx) = broadcast::channel(1024);
        *slot = Some(tx.clone());
        tokio::spawn(poll(self.store.clone(), tx, self.sender.clone(), newest));
        rx
    }
}

/// Asks the store for new parts every [`POLL`] while anyone listens.
async fn poll(
    store: StoreHandle,
    tx: broadcast::Sender<Frame>,
    slot: Arc<Mutex<Option<broadcast::Sender<Frame>>>>,
    mut last: Option<MeasurementId>,
) {
    let mut tick = tokio::time::interval(POLL);
    tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tick.tick().await;
        {
            // Under the lock, so a new listener either sees this poller or starts the next.
            let mut s = slot.lock().unwrap_or_else(|p| p.into_inner());
            if tx.receiver_count() == 0 {
                *s = None;
                return;
            }
        }
        let Some(store) = store.read().await.clone() else {
            continue;
        };
        let Ok(newest) = store.newest_measurement_id().await else {
            continue;
        };
        if newest <= last {
            continue;
        }
        let after = last.unwrap_or(MeasurementId(0));
        let Ok(parts) = store.measurements_after(after, 1000).await else {
            continue;
        };
        for p in &parts {
            // A master run is the gauge study's, an in-process one has stock on: neither is
            // a point of the live trend.
            if trend_point(p) {
                let _ = tx.send(frame(p));
            }
            last = Some(p.id);
        }
    }
}

/// A finished production part: what the live trend shows.
fn trend_point(p: &MeasurementSummary) -> bool {
    !is_master_part(&p.part) && p.stage == crate::store::MeasurementStage::Final
}

fn frame(p: &MeasurementSummary) -> Frame {
    let data = serde_json::to_string(&PartEvent::from(p)).unwrap_or_default();
    (p.id.0, data.into())
}

fn encode((id, data): &Frame) -> String {
    format!("id: {id}\nevent: part\ndata: {data}\n\n")
}

/// `GET /dashboard/events`: the event stream.
#[utoipa::path(get, path = "/dashboard/events", tag = "dashboard", responses((status = 200, description = "each new part as a Server-Sent Event (`Last-Event-ID` resumes)", content_type = "text/event-stream")))]
pub(super) async fn events(
    State(state): State<super::Dash>,
    stopping: Option<axum::Extension<Stopping>>,
    headers: HeaderMap,
) -> Response {
    let rx = state.live.subscribe().await;
    let resume = headers
        .get("last-event-id")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().parse::<i64>().ok());
    // Subscribed first, then caught up: nothing falls between; repeats are skipped by id.
    let mut backlog = Vec::new();
    if let Some(after) = resume
        && let Some(store) = state.app.store.read().await.clone()
        && let Ok(parts) = store
            .measurements_after(MeasurementId(after), CATCH_UP)
            .await
    {
        backlog = parts.iter().filter(|p| trend_point(p)).map(frame).collect();
    }
    let sent = backlog.last().map(|f| f.0).or(resume).unwrap_or(0);
    let first = format!(
        "retry: 1000\n\n{}",
        backlog.iter().map(encode).collect::<String>()
    );
    let stop = stopping.map(|s| s.0.0);
    let body = stream::unfold(
        (Some(first), rx, stop, sent),
        |(first, mut rx, mut stop, mut sent)| async move {
            if let Some(text) = first {
                return Some((Ok::<_, Infallible>(text), (None, rx, stop, sent)));
            }
            loop {
                let next = tokio::select! {
                    r = rx.recv() => r,
                    _ = stopped(&mut stop) => return None,
                    _ = tokio::time::sleep(KEEP_ALIVE) => {
                        return Some((Ok(": keep-alive\n\n".to_string()), (None, rx, stop, sent)));
                    }
                };
                match next {
                    Ok(f) if f.0 <= sent => continue,
                    Ok(f) => {
                        sent = f.0;
                        return Some((Ok(encode(&f)), (None, rx, stop, sent)));
                    }
                    // Too slow a reader: the browser reconnects with its last id and catches up.
                    Err(broadcast::error::RecvError::Lagged(_)) => return None,
                    Err(broadcast::error::RecvError::Closed) => return None,
                }
            }
        },
    );
    (
        [
            (header::CONTENT_TYPE, "text/event-stream"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        axum::body::Body::from_stream(body),
    )
        .into_response()
}

/// Resolves when the server is stopping; never, without a signal.
async fn stopped(stop: &mut Option<watch::Receiver<bool>>) {
    match stop {
        Some(rx) => {
            let _ = rx.wait_for(|s| *s).await;
        }
        None => std::future::pending().await,
    }
}
