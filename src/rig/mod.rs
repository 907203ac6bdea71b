//! Rigs: where trials run. The searches stay in the server and ask a rig
//! for one trial at a time (`zwidth::trial`): the simulator runs it in this
//! process; an attached rig sends it to its agent (`attached`, over the
//! protocol in `protocol`, leased and fenced by `lease`). The plant model
//! itself is numerics (`zwidth_core::plant`).

pub mod attached;
pub mod lease;
pub mod protocol;
pub mod simulator;
pub mod window;

use serde::Serialize;
use std::sync::Arc;

use crate::error::SpecError;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::trial::TrialBackend;
pub use attached::AttachedRig;
pub use simulator::SimulatedRig;

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

    /// The attached rig behind this one, if it is one (its session,
    /// state and capabilities: `GET /v1/rigs`, `GET /v1/agent`).
    fn attached(&self) -> Option<&AttachedRig> {
        None
    }
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

/// `--rigs`: `NAME[:THREADS]` (a simulator) or `NAME:attached` (hardware
/// behind an agent), separated by commas, e.g. `sim:2,bench:attached`.
pub fn parse_list(text: &str) -> Result<Vec<Arc<dyn Rig>>, SpecError> {
    let mut rigs: Vec<Arc<dyn Rig>> = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let (id, what) = part.split_once(':').unwrap_or((part, "0"));
        if rigs.iter().any(|r| r.info().id == id) {
            return Err(SpecError::new("rigs", id, "rig ids must be unique"));
        }
        let rig: Arc<dyn Rig> = if what == "attached" {
            Arc::new(AttachedRig::new(id, "attached rig (from --rigs)")?)
        } else {
            let threads = what.parse::<usize>().map_err(|_| {
                SpecError::new(
                    "rigs",
                    part,
                    "NAME[:THREADS] with THREADS a whole number, or NAME:attached",
                )
            })?;
            Arc::new(SimulatedRig::new(id, threads)?)
        };
        rigs.push(rig);
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A rig that samples at 100 Hz to 1 kHz.
    struct Bench(RigInfo, rayon::ThreadPool);

    impl Rig for Bench {
        fn info(&self) -> RigInfo {
            self.0.clone()
        }
        fn pool(&self) -> &rayon::ThreadPool {
            &self.1
        }
        fn backend(&self, _: &str) -> Option<Arc<dyn TrialBackend>> {
            None
        }
    }

    #[test]
    fn a_rig_refuses_a_scene_it_cannot_run_by_its_field() {
        let scene = |json: &str| SceneSpec::from_json(json).unwrap();
        let scenes = vec![
            (
                "scenes[0]".to_string(),
                scene(r#"{"loop":{"sample_hz":1000,"render_hz":1000}}"#),
            ),
            (
                "scenes[1]".to_string(),
                scene(r#"{"loop":{"sample_hz":5000,"render_hz":1000}}"#),
            ),
        ];
        let info = RigInfo {
            id: "bench".into(),
            kind: "test".into(),
            description: String::new(),
            sample_hz: [100.0, 1000.0],
            force_limit_n: None,
            parallelism: 1,
        };
        let rig = Bench(info.clone(), rig_pool("bench", 1).unwrap());
        assert_eq!(
            rig.check(&scenes).unwrap_err().field,
            "scenes[1].loop.sample_hz"
        );
        assert!(rig.check(&scenes[..1]).is_ok());
        // With a force limit of 2 N, a scene must set one at most that.
        let limited = Bench(
            RigInfo {
                force_limit_n: Some(2.0),
                ..info
            },
            rig_pool("bench2", 1).unwrap(),
        );
        assert_eq!(
            limited.check(&scenes[..1]).unwrap_err().field,
            "scenes[0].device.force_limit"
        );
    }

    #[test]
    fn rig_lists() {
        let r = parse_list("sim:2, night:1, bench:attached").unwrap();
        assert_eq!(r.len(), 3);
        assert_eq!(r[0].info().parallelism, 2);
        assert_eq!(r[1].info().id, "night");
        assert_eq!(r[1].pool().current_num_threads(), 1);
        assert_eq!(r[2].info().kind, "attached");
        assert_eq!(
            r[2].info().parallelism,
            1,
            "hardware runs one trial at a time"
        );
        assert!(r[0].backend("e").is_none() && r[2].backend("e").is_some());
        for bad in [
            "",
            "a:b",
            "sim:1,sim:2",
            "with space",
            "x:1000",
            "x:attached,x:1",
        ] {
            assert_eq!(
                parse_list(bad).err().map(|e| e.field).as_deref(),
                Some("rigs"),
                "{bad}"
            );
        }
    }
}
