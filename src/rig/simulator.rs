//! The simulated rig: the engines on a dedicated rayon pool of its own size,
//! so a rig's parallelism is what it declares and CPU work never lands on
//! the async workers.

use std::sync::Arc;

use super::{Rig, RigInfo};
use crate::error::SpecError;
use crate::experiment::ExperimentSpec;
use crate::zwidth::search::Observer;

pub struct SimulatedRig {
    info: RigInfo,
    pool: rayon::ThreadPool,
}

impl SimulatedRig {
    /// A simulator named `id` running `threads` trials at once (0: one per core).
    pub fn new(id: &str, threads: usize) -> Result<Self, SpecError> {
        if id.is_empty()
            || id.len() > 64
            || !id
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            return Err(SpecError::new(
                "rigs",
                format!("{id:?}"),
                "a rig id is 1 to 64 letters, digits, '-' or '_'",
            ));
        }
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
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name({
                let id = id.to_string();
                move |i| format!("rig-{id}-{i}")
            })
            .build()
            .map_err(|e| SpecError::new("rigs", id, format!("cannot start its threads: {e}")))?;
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
            pool,
        })
    }

    /// Parse `--rigs`: `NAME[:THREADS]` separated by commas, e.g. `sim:2,night:1`.
    pub fn parse_list(text: &str) -> Result<Vec<Self>, SpecError> {
        let mut rigs: Vec<Self> = Vec::new();
        for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let (id, threads) = match part.split_once(':') {
                Some((id, n)) => (
                    id,
                    n.parse::<usize>().map_err(|_| {
                        SpecError::new("rigs", part, "NAME[:THREADS] with THREADS a whole number")
                    })?,
                ),
                None => (part, 0),
            };
            if rigs.iter().any(|r| r.info.id == id) {
                return Err(SpecError::new("rigs", id, "rig ids must be unique"));
            }
            rigs.push(Self::new(id, threads)?);
        }
        if rigs.is_empty() {
            return Err(SpecError::new(
                "rigs",
                format!("{text:?}"),
                "name at least one rig, e.g. sim:2",
            ));
        }
        Ok(rigs)
    }
}

impl Rig for SimulatedRig {
    fn info(&self) -> &RigInfo {
        &self.info
    }

    fn run(
        &self,
        spec: &ExperimentSpec,
        observer: Arc<Observer>,
    ) -> Result<serde_json::Value, SpecError> {
        self.pool.install(|| spec.run(observer))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rig_lists() {
        let r = SimulatedRig::parse_list("sim:2, night:1").unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(r[0].info().parallelism, 2);
        assert_eq!(r[1].info().id, "night");
        assert_eq!(r[1].pool.current_num_threads(), 1);
        for bad in ["", "a:b", "sim:1,sim:2", "with space", "x:1000"] {
            assert_eq!(
                SimulatedRig::parse_list(bad)
                    .err()
                    .map(|e| e.field)
                    .as_deref(),
                Some("rigs"),
                "{bad}"
            );
        }
    }
}
