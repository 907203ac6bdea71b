//! The simulated rig: the engines in this process, on a dedicated rayon
//! pool of its own size, so a rig's parallelism is what it declares and CPU
//! work never lands on the async workers.

use std::sync::Arc;

use super::base::{check_id, rig_pool, Rig, RigInfo};
use crate::error::SpecError;
use crate::zwidth::trial::TrialBackend;

pub struct SimulatedRig {
    info: RigInfo,
    pool: rayon::ThreadPool,
}

impl SimulatedRig {
    /// A simulator named `id` running `threads` trials at once (0: one per core).
    pub fn new(id: &str, threads: usize) -> Result<Self, SpecError> {
        check_id("rigs", id)?;
        let threads = if threads == 0 {
            std::thread::available_parallelism().map_or(1, |n| n.get())
        } else {
            threads
        };
        if threads > 256 {
            return Err(SpecError::new(
                "rigs",
                threads,
                "at most 256 threads per rig",
            ));
        }
        Ok(Self {
            info: RigInfo {
                id: id.into(),
                kind: "simulator".into(),
                description: "simulated device and loop of each scene: exact ZOH plant, Coulomb friction, quantization, saturation, delay".into(),
                // The scene validation's own range.
                sample_hz: [10.0, 1e7],
                force_limit_n: None,
                parallelism: threads,
            },
            pool: rig_pool(id, threads)?,
        })
    }
}

impl Rig for SimulatedRig {
    fn info(&self) -> RigInfo {
        self.info.clone()
    }

    fn pool(&self) -> &rayon::ThreadPool {
        &self.pool
    }

    /// Trials run in this process.
    fn backend(&self, _experiment: &str) -> Option<Arc<dyn TrialBackend>> {
        None
    }

    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}
