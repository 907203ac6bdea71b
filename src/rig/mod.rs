//! Rigs: where trials run. The searches stay in the server and ask a rig
//! for one trial at a time (`zwidth::trial`): the simulator runs it in this
//! process; an attached rig sends it to its agent (`attached`, over the
//! protocol in `protocol`, leased and fenced by `lease`). The plant model
//! itself is numerics (`zwidth_core::plant`).

pub mod attached;
pub mod base;
pub mod lease;
pub mod protocol;
pub mod simulator;
pub mod window;

use std::sync::Arc;

use crate::error::SpecError;
pub use attached::AttachedRig;
pub use base::{check_id, check_scene, rig_pool, Rig, RigInfo};
pub use simulator::SimulatedRig;

impl<'a> dyn Rig + 'a {
    /// The attached rig behind this one, if it is one (its session,
    /// state and capabilities: `GET /v1/rigs`, `GET /v1/agent`).
    pub fn attached(&self) -> Option<&AttachedRig> {
        self.as_any().downcast_ref::<AttachedRig>()
    }
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
    use crate::zwidth::scene::SceneSpec;
    use crate::zwidth::trial::TrialBackend;

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
        fn as_any(&self) -> &dyn std::any::Any {
            self
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
