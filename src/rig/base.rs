//! What every rig is: the [`Rig`] trait (its info, the threads of its
//! experiment, where its trials run), and the checks of a rig id and of a
//! scene against what a rig can do.

use serde::Serialize;
use std::sync::Arc;

use crate::error::SpecError;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::trial::TrialBackend;

/// What a rig can do, as the API lists it.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct RigInfo {
    pub id: String,
    /// "simulator" or "attached" (hardware behind a `zwidth agent`).
    pub kind: String,
    pub description: String,
    /// Encoder sample rates it runs (Hz): [lowest, highest].
    pub sample_hz: [f64; 2],
    /// Largest force it can exert (N); null: no limit beyond the scene's own.
    pub force_limit_n: Option<f64>,
    /// Trials it runs at once. A rig runs one experiment at a time.
    pub parallelism: usize,
}

/// Something that runs an experiment's trials, one experiment at a time.
pub trait Rig: Send + Sync {
    fn info(&self) -> RigInfo;

    /// Whether the rig can run these scenes (named by their field): rates,
    /// force, what an attached rig advertises.
    fn check(&self, scenes: &[(String, SceneSpec)]) -> Result<(), SpecError> {
        let info = self.info();
        for (field, scene) in scenes {
            check_scene(&info, scene).map_err(|e| e.within(field))?;
        }
        Ok(())
    }

    /// The threads the searches of one experiment run on (the rig's
    /// parallelism), off the async workers.
    fn pool(&self) -> &rayon::ThreadPool;

    /// Where experiment `experiment`'s trials run; None: in this process.
    fn backend(&self, experiment: &str) -> Option<Arc<dyn TrialBackend>>;

    /// This rig as `Any`, for `attached()` on `dyn Rig` (`rig/mod.rs`):
    /// the attached rig behind it, if it is one.
    fn as_any(&self) -> &dyn std::any::Any;
}

/// A dedicated pool of `threads` named after rig `id`.
pub fn rig_pool(id: &str, threads: usize) -> Result<rayon::ThreadPool, SpecError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name({
            let id = id.to_string();
            move |i| format!("rig-{id}-{i}")
        })
        .build()
        .map_err(|e| SpecError::new("rigs", id, format!("cannot start its threads: {e}")))
}

/// A rig id: 1 to 64 letters, digits, '-' or '_'.
pub fn check_id(field: &str, id: &str) -> Result<(), SpecError> {
    if id.is_empty()
        || id.len() > 64
        || !id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    {
        return Err(SpecError::new(
            field,
            format!("{id:?}"),
            "a rig id is 1 to 64 letters, digits, '-' or '_'",
        ));
    }
    Ok(())
}

/// A scene's rates and force against a rig's capabilities.
pub fn check_scene(info: &RigInfo, scene: &SceneSpec) -> Result<(), SpecError> {
    let hz = scene.control.sample_hz;
    if !(info.sample_hz[0]..=info.sample_hz[1]).contains(&hz) {
        return Err(SpecError::new(
            "loop.sample_hz",
            hz,
            format!(
                "rig {} samples at {} to {} Hz",
                info.id, info.sample_hz[0], info.sample_hz[1]
            ),
        ));
    }
    if let Some(limit) = info.force_limit_n {
        match scene.device.force_limit {
            Some(f) if f <= limit => {}
            f => {
                return Err(SpecError::new(
                    "device.force_limit",
                    f.map(|f| f.to_string()).unwrap_or("null".into()),
                    format!(
                        "rig {} exerts at most {limit} N: set a force_limit <= {limit}",
                        info.id
                    ),
                ))
            }
        }
    }
    Ok(())
}
