//! The queue page: per rig its window, pause and connection; what runs
//! (progress, trials/s, ETA), what waits in claim order, what failed in the
//! last 24 h. Actions: cancel, pause/resume, a rig's window.

use axum::extract::{RawQuery, State};
use axum::response::Response;
use maud::{html, Markup};

use super::{action, ago, duration, fragment, live_part, run_link, state_badge, unchanged, Nav};
use crate::clock::now_ms;
use crate::http::rigs::{rig_view, RigView};
use crate::http::{AppState, Problem};

/// Rows shown of the waiting and the failed.
const SHOWN: i64 = 50;
/// The failures shown: those of the last day (ms).
const DAY_MS: i64 = 24 * 3600 * 1000;

pub async fn page(State(st): State<AppState>) -> Result<Response, Problem> {
    Ok(page_with(current(&st).await?))
}

fn page_with(live: Markup) -> Response {
    super::layout(
        "Queue",
        Nav::Queue,
        html! {
            h1 { "Queue" }
            (live)
        },
    )
}

/// `GET /ui/queue/live?since=…`: the live part, or 204 when unchanged.
pub async fn live(State(st): State<AppState>, RawQuery(q): RawQuery) -> Result<Response, Problem> {
    let token = token(&st).await?;
    if let Some(r) = unchanged(q.as_deref(), &token) {
        return Ok(r);
    }
    Ok(fragment(render(&st, &token).await?))
}

async fn current(st: &AppState) -> Result<Markup, Problem> {
    let token = token(st).await?;
    render(st, &token).await
}

/// The board's token plus what only this process knows: the running
/// runs' rig status (held, waiting for the rig), the rigs' windows (and
/// whether each is open now) and attached rigs' connections.
pub(super) async fn token(st: &AppState) -> Result<String, Problem> {
    use std::hash::{Hash, Hasher};
    let now = now_ms();
    let t = st
        .store
        .board_token(now, now - DAY_MS)
        .await
        .map_err(|e| st.fail(e))?;
    let mut h = std::collections::hash_map::DefaultHasher::new();
    {
        let running = st.running.lock().unwrap_or_else(|e| e.into_inner());
        let mut status: Vec<(String, Option<String>, Option<String>)> = running
            .iter()
            .map(|(id, o)| (id.clone(), o.held(), o.waiting()))
            .collect();
        status.sort();
        status.hash(&mut h);
    }
    let windows = st.store.rig_windows().await.map_err(|e| st.fail(e))?;
    windows.hash(&mut h);
    let at = jiff::Timestamp::from_millisecond(now).unwrap_or_else(|_| jiff::Timestamp::now());
    for (_, w) in &windows {
        let open = serde_json::from_str::<crate::rig::window::Window>(w)
            .ok()
            .and_then(|w| w.validate().ok())
            .is_some_and(|h| h.is_open(at));
        open.hash(&mut h);
    }
    for r in st.rig_list() {
        r.info().id.hash(&mut h);
        r.attached()
            .map(|a| a.view())
            .map(|a| {
                (
                    a.connected,
                    a.lost_contact,
                    a.quarantine,
                    a.state.map(|s| format!("{s:?}")),
                )
            })
            .hash(&mut h);
    }
    Ok(format!("{t}.{:x}", h.finish()))
}

async fn render(st: &AppState, token: &str) -> Result<Markup, Problem> {
    let now = now_ms();
    let board = st
        .store
        .board(now, now - DAY_MS, SHOWN)
        .await
        .map_err(|e| st.fail(e))?;
    let paused = st.store.paused().await.map_err(|e| st.fail(e))?;
    let mut rigs: Vec<RigView> = Vec::new();
    for r in st.rig_list() {
        rigs.push(rig_view(st, &r).await?);
    }
    let inner = html! {
        div class="bar" {
            @if paused {
                p class="paused" { strong { "The queue is paused:" } " nothing new starts; running experiments go on." }
                (action("POST", "/v1/queue/resume", "Resume", "the queue"))
            } @else {
                p { "The queue is running." }
                (action("POST", "/v1/queue/pause", "Pause", "the queue"))
            }
        }
        h2 { "Rigs" }
        table class="rigs" {
            thead { tr { th { "rig" } th { "kind" } th { "window" } th { "connected" } th { "waiting" } th { "running" } th { span class="sr" { "actions" } } } }
            tbody {
                @for r in &rigs { (rig_row(r, now)) }
            }
        }
        h2 { "Running " span class="count" { "(" (board.running.len()) ")" } }
        @if board.running.is_empty() {
            p class="muted" { "Nothing is running." }
        } @else {
            table class="running" {
                thead { tr { th { "run" } th { "kind" } th { "rig" } th { "progress" } th { "trials" } th { "trials/s" } th { "ETA" } th { "worker" } th { span class="sr" { "actions" } } } }
                tbody {
                    @for r in &board.running {
                        @let v = st.view(r.clone());
                        @let elapsed = v.progress["elapsed_s"].as_f64();
                        tr {
                            td { (run_link(&r.id)) }
                            td { (r.kind) }
                            td { (r.rig) }
                            td class="volatile" { progress value=(format!("{:.3}", r.progress)) max="1" aria-label={"progress of " (r.id)} {} " " span class="num" { (format!("{:.0} %", 100.0 * r.progress)) } }
                            td class="num volatile" { (r.trials_done) }
                            td class="num volatile" { (elapsed.filter(|e| *e > 0.5).map_or("–".into(), |e| format!("{:.1}", r.trials_done as f64 / e))) }
                            td class="volatile" {
                                @if let Some(why) = v.progress["waiting_for_rig"].as_str() { span class="warn" { "waiting for the rig: " (why) } }
                                @else { (v.progress["eta_s"].as_f64().map_or("–".into(), duration)) }
                            }
                            td class="mono small volatile" { (r.worker.as_deref().unwrap_or("–")) }
                            td { (action("POST", &format!("/v1/experiments/{}/cancel", r.id), "Cancel", &r.id)) }
                        }
                    }
                }
            }
        }
        h2 { "Waiting " span class="count" { "(" (board.waiting_total) ")" } }
        @if board.waiting.is_empty() {
            p class="muted" { "Nothing is waiting." }
        } @else {
            p class="muted small" { "In the order they will be claimed on each rig: runnable now by priority then age, then those that become runnable later (scheduled, or interrupted until their last lease ends) by that time." }
            table class="waiting" {
                thead { tr { th { "rig" } th { "#" } th { "run" } th { "kind" } th { "priority" } th { "state" } th { "submitted" } th { "runnable" } th { span class="sr" { "actions" } } } }
                tbody {
                    @for (r, n) in board.waiting.iter().zip(per_rig_order(&board.waiting)) {
                        @let ready = ready_at(r, now);
                        tr {
                            td { (r.rig) }
                            td class="num" { (n) }
                            td { (run_link(&r.id)) }
                            td { (r.kind) }
                            td class="num" { (r.priority) }
                            td { (state_badge(r.state)) }
                            td class="volatile" { (ago(r.created_ms, now)) }
                            td class="volatile" { (ready.map_or("now".into(), |t| format!("in {}", duration((t - now) as f64 / 1000.0)))) }
                            td { (action("POST", &format!("/v1/experiments/{}/cancel", r.id), "Cancel", &r.id)) }
                        }
                    }
                }
            }
            @if board.waiting_total > board.waiting.len() as i64 {
                p class="muted" { "and " (board.waiting_total - board.waiting.len() as i64) " more: " a href="/runs?state=queued" { "all queued runs" } }
            }
        }
        h2 { "Failed in the last 24 h " span class="count" { "(" (board.failed_total) ")" } }
        @if board.failed.is_empty() {
            p class="muted" { "No failures." }
        } @else {
            table class="failed" {
                thead { tr { th { "run" } th { "kind" } th { "rig" } th { "ended" } th { "message" } } }
                tbody {
                    @for r in &board.failed {
                        tr {
                            td { (run_link(&r.id)) }
                            td { (r.kind) }
                            td { (r.rig) }
                            td class="volatile" { (r.finished_ms.map_or("–".into(), |t| ago(t, now))) }
                            td class="error" { (r.error.as_deref().unwrap_or("")) }
                        }
                    }
                }
            }
            @if board.failed_total > board.failed.len() as i64 {
                p class="muted" { "and " (board.failed_total - board.failed.len() as i64) " more: " a href="/runs?state=failed" { "all failed runs" } }
            }
        }
    };
    Ok(live_part("live", "/ui/queue/live", token, true, inner))
}

/// A rig's row: its window in its own time zone and the form to edit it.
fn rig_row(r: &RigView, now: i64) -> Markup {
    let id = &r.info.id;
    let window = match &r.window {
        None => html! { "always open" },
        Some(w) => {
            let opens = if r.open_now {
                "open now".to_string()
            } else {
                format!(
                    "opens in {}",
                    duration((r.next_start_ms - now) as f64 / 1000.0)
                )
            };
            html! { (w.start) "–" (w.end) " " span class="muted" { (w.tz) } br; span class={"volatile " (if r.open_now { "ok" } else { "warn" })} { (opens) } }
        }
    };
    let connected = match &r.attached {
        None => html! { span class="muted" { "– (simulator)" } },
        Some(a) if a.connected && !a.lost_contact => html! { span class="ok" { "connected" } },
        Some(a) if a.lost_contact => html! { span class="warn" { "lost contact" } },
        Some(_) => html! { span class="bad" { "not connected" } },
    };
    let w = r.window.clone();
    let form_id = format!("window-{id}");
    html! {
        tr {
            td { (id) br; span class="muted small" { (r.info.description) } }
            td { (r.info.kind) }
            td { (window) }
            td { (connected)
                @if let Some(q) = r.attached.as_ref().and_then(|a| a.quarantine.as_deref()) { br; span class="bad" { "quarantined: " (q) } }
                @if let Some(c) = r.attached.as_ref().and_then(|a| a.estimators.as_ref()).filter(|c| !c.identical) { br; span class="warn" { "estimators: " (c.summary) } }
            }
            td class="num" { (r.waiting) }
            td { @if let Some(run) = &r.running { (run_link(run)) } @else { "–" } }
            td {
                // Kept as it is when the live part is redrawn (open, typed).
                details id={"window-edit-" (id)} hx-preserve="true" {
                    summary { "Window" }
                    form id=(form_id) class="window" data-rig=(id) {
                        label { "opens " input name="start" type="time" required value=(w.as_ref().map_or("22:00", |w| w.start.as_str())); }
                        label { "closes " input name="end" type="time" required value=(w.as_ref().map_or("06:00", |w| w.end.as_str())); }
                        label { "time zone " input name="tz" type="text" size="16" value=(w.as_ref().map_or("UTC", |w| w.tz.as_str())); }
                        button type="submit" { "Set" }
                        @if w.is_some() { (action("DELETE", &format!("/v1/rigs/{id}/window"), "Clear", &format!("the window of {id}"))) }
                    }
                }
            }
        }
    }
}

/// Each run's place in its own rig's queue (1, 2, … per rig), in the
/// board's order.
pub fn per_rig_order(rows: &[crate::store::ExperimentRow]) -> Vec<usize> {
    let mut seen: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
    rows.iter()
        .map(|r| {
            let n = seen.entry(r.rig.as_str()).or_insert(0);
            *n += 1;
            *n
        })
        .collect()
}

/// When a waiting run becomes claimable, if later than `now`: its
/// `not_before`, or an interrupted run's last lease end.
pub fn ready_at(r: &crate::store::ExperimentRow, now: i64) -> Option<i64> {
    let lease = (r.state == crate::store::ExperimentState::Interrupted)
        .then_some(r.lease_until_ms)
        .flatten();
    [r.not_before_ms, lease]
        .into_iter()
        .flatten()
        .filter(|t| *t > now)
        .max()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::ExperimentRow;

    fn row(rig: &str, state: &str, not_before: Option<i64>, lease: Option<i64>) -> ExperimentRow {
        ExperimentRow {
            id: "x".into(),
            kind: "map".into(),
            spec: String::new(),
            state: state.parse().unwrap(),
            priority: 0,
            created_ms: 0,
            started_ms: None,
            finished_ms: None,
            trials_done: 0,
            result: None,
            error: None,
            idempotency_key: None,
            not_before_ms: not_before,
            rig: rig.into(),
            progress: 0.0,
            best: None,
            attempt: 0,
            worker: None,
            lease_until_ms: lease,
        }
    }

    #[test]
    fn places_count_per_rig_and_readiness_is_the_later_of_schedule_and_lease() {
        let rows = [
            row("a", "queued", None, None),
            row("b", "queued", None, None),
            row("a", "queued", None, None),
            row("a", "scheduled", None, None),
            row("b", "queued", None, None),
        ];
        assert_eq!(per_rig_order(&rows), vec![1, 1, 2, 3, 2]);
        let now = 1_000;
        assert_eq!(ready_at(&row("a", "queued", None, None), now), None);
        assert_eq!(
            ready_at(&row("a", "scheduled", Some(500), None), now),
            None,
            "past: now"
        );
        assert_eq!(
            ready_at(&row("a", "scheduled", Some(5_000), None), now),
            Some(5_000)
        );
        // An interrupted run waits for its last lease to end (the claim's
        // rule); a queued one's stale lease does not count.
        assert_eq!(
            ready_at(&row("a", "interrupted", None, Some(3_000)), now),
            Some(3_000)
        );
        assert_eq!(ready_at(&row("a", "queued", None, Some(3_000)), now), None);
        assert_eq!(
            ready_at(&row("a", "interrupted", Some(9_000), Some(3_000)), now),
            Some(9_000)
        );
    }
}
