//! Rigs: what runs an experiment. The simulated device (the plant between
//! force updates) lives in `crate::plant`; a [`Rig`] is anything that can run a
//! whole experiment: today the simulator, later attached hardware.

pub mod simulator;
pub mod window;

use serde::Serialize;
use std::sync::Arc;

use crate::error::SpecError;
use crate::experiment::ExperimentSpec;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::Observer;
pub use simulator::SimulatedRig;

/// What a rig can do, as the API lists it.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct RigInfo {
    pub id: String,
    /// "simulator" (attached hardware rigs come later).
    pub kind: String,
    pub description: String,
    /// Encoder sample rates it runs (Hz): [lowest, highest].
    pub sample_hz: [f64; 2],
    /// Largest force it can exert (N); null: no limit beyond the scene's own.
    pub force_limit_n: Option<f64>,
    /// Trials it runs at once. A rig runs one experiment at a time.
    pub parallelism: usize,
}

/// Something that runs experiments, one at a time.
pub trait Rig: Send + Sync {
    fn info(&self) -> &RigInfo;

    /// Whether the rig can run every scene of the experiment (rates, force).
    fn check(&self, spec: &ExperimentSpec) -> Result<(), SpecError> {
        let info = self.info();
        for (field, scene) in spec.scenes() {
            check_scene(info, &scene).map_err(|e| e.within(&field))?;
        }
        Ok(())
    }

    /// Run to completion (blocking; call off the async workers), reporting
    /// trials to and honouring cancellation from `observer`.
    fn run(
        &self,
        spec: &ExperimentSpec,
        observer: Arc<Observer>,
    ) -> Result<serde_json::Value, SpecError>;
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
