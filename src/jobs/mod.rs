//! The experiment queue: what an experiment is (one spec type, stored as
//! submitted), and the runner that claims queued experiments one at a time,
//! runs them off the async workers (`spawn_blocking`), writes progress, and
//! honours cancellation between trials.

use serde::{Deserialize, Serialize};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use crate::error::SpecError;
use crate::store::Store;
use crate::zwidth::compare;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::{self, map_observed, Observer};
use crate::zwidth::settings::{Accuracy, MapSpec};

/// An experiment as submitted: `{"kind":"map", …MapSpec}` or
/// `{"kind":"compare","scene":{…},"accuracy":"draft"}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ExperimentSpec {
    Map(MapSpec),
    Compare(CompareSpec),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CompareSpec {
    /// The scene (its estimator is ignored); default the 2018 paper's simulated device.
    #[serde(default)]
    pub scene: Option<SceneSpec>,
    #[serde(default)]
    pub accuracy: Accuracy,
}

impl ExperimentSpec {
    pub fn kind(&self) -> &'static str {
        match self {
            ExperimentSpec::Map(_) => "map",
            ExperimentSpec::Compare(_) => "compare",
        }
    }

    /// The engines' own validation, without running anything.
    pub fn validate(&self) -> Result<(), SpecError> {
        match self {
            ExperimentSpec::Map(m) => search::validate(m),
            ExperimentSpec::Compare(c) => {
                let scene = c.scene.clone().unwrap_or_else(compare::seed_2018_scene);
                let sc = scene.validate().map_err(|e| e.within("scene"))?;
                c.accuracy.resolve(&sc).map(|_| ())
            }
        }
    }

    /// Run to completion (blocking; call off the async workers).
    pub fn run(&self, observer: Arc<Observer>) -> Result<serde_json::Value, SpecError> {
        // Results are plain data: serializing them cannot fail.
        match self {
            ExperimentSpec::Map(m) => map_observed(m, Some(observer), 0)
                .map(|r| serde_json::to_value(r).unwrap_or_default()),
            ExperimentSpec::Compare(c) => {
                let scene = c.scene.clone().unwrap_or_else(compare::seed_2018_scene);
                compare::compare_observed(&scene, &c.accuracy, Some(observer))
                    .map(|r| serde_json::to_value(r).unwrap_or_default())
            }
        }
    }
}

/// Trials per second of the running experiment over the last second (for /metrics).
pub static TRIALS_PER_SECOND: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Claim and run experiments until the process ends.
pub async fn runner(store: Store) {
    loop {
        match store.claim_next().await {
            Ok(Some(row)) => run_one(&store, row.id, row.spec).await,
            Ok(None) => tokio::time::sleep(Duration::from_millis(100)).await,
            Err(e) => {
                tracing::error!(error = %e, "claiming the next experiment failed");
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

#[tracing::instrument(skip(store, spec))]
async fn run_one(store: &Store, id: String, spec: String) {
    let parsed: ExperimentSpec = match serde_json::from_str(&spec) {
        Ok(s) => s,
        Err(e) => {
            let _ = store
                .finish(
                    &id,
                    "failed",
                    0,
                    None,
                    Some(&format!("stored spec unreadable: {e}")),
                )
                .await;
            return;
        }
    };
    // Resume: trials stored by an interrupted run are replayed, not redone.
    let done = match store.trials(&id).await {
        Ok(t) => t,
        Err(e) => {
            tracing::error!(error = %e, "reading stored trials failed");
            Vec::new()
        }
    };
    if !done.is_empty() {
        tracing::info!(stored = done.len(), "resuming from stored trials");
    }
    let observer = Arc::new(Observer::resuming(done));
    let obs = observer.clone();
    let mut task = tokio::task::spawn_blocking(move || parsed.run(obs));
    // Every 100 ms: store the trials finished since (one transaction), write
    // progress, and look for a cancel request.
    let mut rate_mark = (std::time::Instant::now(), 0usize);
    let outcome = loop {
        tokio::select! {
            r = &mut task => break r,
            _ = tokio::time::sleep(Duration::from_millis(100)) => {
                if let Err(e) = store.add_trials(&id, &observer.take_new()).await {
                    tracing::warn!(error = %e, "storing trials failed");
                }
                let trials = observer.trials.load(Ordering::Relaxed) as i64;
                let dt = rate_mark.0.elapsed().as_secs_f64();
                if dt >= 1.0 {
                    TRIALS_PER_SECOND.store(((trials as usize - rate_mark.1) as f64 / dt).round() as u64, Ordering::Relaxed);
                    rate_mark = (std::time::Instant::now(), trials as usize);
                }
                if let Err(e) = store.set_progress(&id, trials).await {
                    tracing::warn!(error = %e, "progress write failed");
                }
                if let Ok(Some(state)) = store.state(&id).await {
                    if state == "cancelled" {
                        observer.cancel.store(true, Ordering::Relaxed);
                    }
                }
            }
        }
    };
    if let Err(e) = store.add_trials(&id, &observer.take_new()).await {
        tracing::warn!(error = %e, "storing trials failed");
    }
    TRIALS_PER_SECOND.store(0, Ordering::Relaxed);
    let trials = observer.trials.load(Ordering::Relaxed) as i64;
    let res = if observer.cancelled() {
        store.finish(&id, "cancelled", trials, None, None).await
    } else {
        match outcome {
            Ok(Ok(v)) => {
                store
                    .finish(&id, "succeeded", trials, Some(&v.to_string()), None)
                    .await
            }
            Ok(Err(e)) => {
                store
                    .finish(&id, "failed", trials, None, Some(&e.to_string()))
                    .await
            }
            Err(e) => {
                store
                    .finish(
                        &id,
                        "failed",
                        trials,
                        None,
                        Some(&format!("the run panicked: {e}")),
                    )
                    .await
            }
        }
    };
    if let Err(e) = res {
        tracing::error!(error = %e, "recording the end of a run failed");
    }
}
