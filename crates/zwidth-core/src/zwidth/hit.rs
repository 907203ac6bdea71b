//! The time-domain engine: one automated wall hit (2011 paper §2.4).
//!
//! The handle starts `home_distance` before the wall at rest; a constant
//! `push_force` drives it in. Every encoder sample the position is quantized
//! and the estimator updated; every render period the wall force
//! `−(K(y − x_wall) + B·v̂)` is computed while the measured y is past the wall
//! (else 0, 2011 eq. 12), delayed by `delay_samples` render periods, added to
//! the push force, saturated, and held. `settle_s` after the first contact
//! (the paper counts from the start; the 7 cm approach then eats 2.6 of its
//! 4 s, and a shorter setting would measure before the handle arrives; a
//! push that cannot beat friction never arrives and is measured at once) the
//! RMS of the measured position about its mean over `measure_s` decides:
//! stable iff below `threshold`. A trial that diverges (|x| > 10 m, |v| > 1e3 m/s) stops
//! at once and is unstable.
//!
//! With friction, a handle held stuck for 0.2 s with the wall force well
//! inside the friction band and B·v̂ small stays stuck (its measured position
//! cannot change, so neither can the spring force): the trial ends there and
//! the rest of the window is counted as that constant position.
//!
//! Only what the scene has is simulated: without friction the plant step is
//! the exact ZOH update with no event handling; without quantization there is
//! no rounding (const-generic variants of one loop).

use serde::Serialize;

use super::controller::Controller;
use super::scene::Scene;
use crate::signals::quantize;

/// Time-domain knobs the accuracy setting may override.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HitKnobs {
    pub settle_s: f64,
    pub measure_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HitOutcome {
    pub stable: bool,
    /// RMS of the measured position about its mean in the measure window (m);
    /// none when the trial diverged before it.
    pub rms: Option<f64>,
    pub mean_position: f64,
    pub diverged: bool,
    /// Samples simulated.
    pub samples: usize,
    /// Render updates whose force the device's force limit clipped.
    pub saturated_renders: u64,
}

/// One row of a trial trace.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TraceRow {
    pub t: f64,
    pub x: f64,
    pub y: f64,
    pub v_est: f64,
    pub v: f64,
    pub force: f64,
}

/// Where trace rows go; the no-op recorder compiles away.
pub trait Recorder {
    fn record(&mut self, row: TraceRow);
}

pub struct NoTrace;

impl Recorder for NoTrace {
    #[inline(always)]
    fn record(&mut self, _: TraceRow) {}
}

impl Recorder for Vec<TraceRow> {
    fn record(&mut self, row: TraceRow) {
        self.push(row);
    }
}

const DIVERGED_X: f64 = 10.0;
const DIVERGED_V: f64 = 1e3;

/// One wall hit with stiffness `k` (N/m) and damping `b` (N·s/m), already validated.
pub fn wall_hit(
    scene: &Scene,
    k: f64,
    b: f64,
    knobs: HitKnobs,
    rec: &mut impl Recorder,
) -> HitOutcome {
    replicate_hit(scene, k, b, knobs, 0, rec)
}

/// Replicate `r` of `hit.replicates`: the hit from `r/R` of an encoder step
/// (1 µm with an ideal sensor) farther from the wall (`HitSpec::replicates`).
pub fn replicate_hit(
    scene: &Scene,
    k: f64,
    b: f64,
    knobs: HitKnobs,
    r: u32,
    rec: &mut impl Recorder,
) -> HitOutcome {
    let d = &scene.spec.device;
    let step = if d.quantization > 0.0 {
        d.quantization
    } else {
        1e-6
    };
    let home = scene.spec.hit.home_distance
        + step * f64::from(r) / f64::from(scene.spec.hit.replicates.max(1));
    match (d.coulomb > 0.0, d.quantization > 0.0) {
        (true, true) => run::<true, true, true>(scene, k, b, knobs, home, rec),
        (true, false) => run::<true, false, true>(scene, k, b, knobs, home, rec),
        (false, true) => run::<false, true, true>(scene, k, b, knobs, home, rec),
        (false, false) => run::<false, false, true>(scene, k, b, knobs, home, rec),
    }
}

/// The verdict of `hit.replicates` hits (`HitSpec::replicates`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Replicated {
    /// Hits run and hits stable.
    pub hits: u32,
    pub stable: u32,
    /// Any hit's force was clipped by the force limit.
    pub saturated: bool,
}

impl Replicated {
    /// The majority (a tie is unstable).
    pub fn stable(&self) -> bool {
        2 * self.stable > self.hits
    }

    /// Every hit agreed.
    pub fn decided(&self) -> bool {
        self.stable == 0 || self.stable == self.hits
    }
}

pub fn replicated_hits(scene: &Scene, k: f64, b: f64, knobs: HitKnobs) -> Replicated {
    let hits = scene.spec.hit.replicates.max(1);
    let mut out = Replicated {
        hits,
        stable: 0,
        saturated: false,
    };
    for r in 0..hits {
        let o = replicate_hit(scene, k, b, knobs, r, &mut NoTrace);
        out.stable += u32::from(o.stable);
        out.saturated |= o.saturated_renders > 0;
    }
    out
}

/// `EARLY`: end a trial once friction holds the handle (module doc); off
/// only to check that shortcut against the full-length run.
fn run<const FRICTION: bool, const QUANT: bool, const EARLY: bool>(
    scene: &Scene,
    k: f64,
    b: f64,
    knobs: HitKnobs,
    home_distance: f64,
    rec: &mut impl Recorder,
) -> HitOutcome {
    let s = &scene.spec;
    let plant = s.device.plant(scene.dt);
    let q = s.device.quantization;
    let wall = s.wall.position;
    let push = s.hit.push_force;
    let limit = s.device.force_limit.unwrap_or(f64::INFINITY);
    let mut ctl = Controller::new(scene, k, b, push, true);
    let settle = (knobs.settle_s / scene.dt).round() as usize;
    let measure = (knobs.measure_s / scene.dt).round().max(1.0) as usize;
    // Settling counts from the first contact. A push that cannot overcome
    // friction never moves the handle: measure right after `settle`. Else
    // wait for contact up to ten times the approach time (terminal-velocity
    // estimate), then measure anyway.
    // With a transmission the push moves both masses against both dampers.
    let dev = &s.device;
    let (mass, damping) = dev
        .transmission
        .as_ref()
        .map_or((dev.mass, dev.damping), |t| {
            (dev.mass + t.motor_mass, dev.damping + t.motor_damping)
        });
    // (With LuGre friction a push above F_c but below F_s may break loose
    // or not, depending on how fast the force rises: wait for it.)
    let drive = push.abs().min(limit) - dev.coulomb;
    let will_move = push > 0.0 && drive > 0.0 && home_distance > 0.0;
    let approach_s = if !will_move {
        0.0
    } else if damping > 0.0 {
        home_distance * damping / drive + mass / damping
    } else {
        (2.0 * home_distance * mass / drive).sqrt()
    };
    let cap = ((10.0 * approach_s + 1.0) / scene.dt).min(1e9) as usize;
    let mut measure_from = if will_move { usize::MAX } else { settle };
    let mut total = if will_move {
        cap + settle + measure
    } else {
        settle + measure
    };
    let mut touched = false;
    let mut st = plant.at_rest(wall - home_distance);
    // Welford mean/variance of y over the measure window.
    let (mut n, mut mean, mut m2) = (0.0f64, 0.0f64, 0.0f64);
    let (mut stuck_for, mut last_y) = (0usize, f64::NAN);
    let stuck_limit = (0.2 / scene.dt).ceil() as usize;
    let mut i = 0usize;
    while i < total {
        let y = if QUANT {
            quantize(plant.encoder(&st), q)
        } else {
            plant.encoder(&st)
        };
        if measure_from == usize::MAX {
            // Not measuring yet: waiting for the first contact (or the cap).
            if y > wall {
                touched = true;
                measure_from = i + settle;
                total = measure_from + measure;
            } else if i >= cap {
                measure_from = i;
                total = i + measure;
            }
        } else if !touched && y > wall {
            touched = true;
        }
        let v_est = ctl.sample(y);
        let applied = ctl.applied;
        rec.record(TraceRow {
            t: i as f64 * scene.dt,
            x: st.x,
            y,
            v_est,
            v: st.v,
            force: applied,
        });
        if i >= measure_from {
            n += 1.0;
            let dlt = y - mean;
            mean += dlt / n;
            m2 += dlt * (y - mean);
        }
        if FRICTION {
            plant.step_driven(&mut st, applied, 0.0, true);
            // Stuck: friction holds the handle, the measured position cannot
            // change, so the wall force changes only through B·v̂, which
            // decays. Held for 0.2 s with the force well inside the friction
            // band, it stays stuck: the rest of the trial is y constant.
            // (Behind an amplifier lag too: stuck means the delivered force
            // was inside the band over the step, and from there it moves
            // monotonically towards the command, also inside it.)
            let held = st.v == 0.0
                && applied.abs() <= 0.9 * s.device.coulomb
                && (b * v_est).abs() <= 0.05 * s.device.coulomb;
            stuck_for = if held && y == last_y {
                stuck_for + 1
            } else {
                0
            };
            last_y = y;
            if EARLY && stuck_for >= stuck_limit && touched && total > i + 1 {
                // Append the remaining samples (at least one: `total > i + 1`)
                // of constant y to the measure window (Welford merge);
                // samples before the window do not count.
                let start = measure_from.max(i + 1);
                let counted = (total - start) as f64;
                if counted > 0.0 {
                    let nb = counted;
                    let dlt = y - mean;
                    let nn = n + nb;
                    mean += dlt * nb / nn;
                    m2 += dlt * dlt * n * nb / nn;
                    n = nn;
                }
                let rms = (m2 / n.max(1.0)).max(0.0).sqrt();
                return HitOutcome {
                    stable: rms < s.hit.threshold,
                    rms: Some(rms),
                    mean_position: mean,
                    diverged: false,
                    samples: i + 1,
                    saturated_renders: ctl.saturated,
                };
            }
        } else {
            plant.step_driven(&mut st, applied, 0.0, false);
        }
        if !(st.x.abs() < DIVERGED_X && st.v.abs() < DIVERGED_V) {
            return HitOutcome {
                stable: false,
                rms: None,
                mean_position: mean,
                diverged: true,
                samples: i + 1,
                saturated_renders: ctl.saturated,
            };
        }
        i += 1;
    }
    let rms = (m2 / n.max(1.0)).max(0.0).sqrt();
    HitOutcome {
        stable: rms < s.hit.threshold,
        rms: Some(rms),
        mean_position: mean,
        diverged: false,
        samples: total,
        saturated_renders: ctl.saturated,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zwidth::scene::SceneSpec;

    fn knobs(s: &Scene) -> HitKnobs {
        HitKnobs {
            settle_s: s.spec.hit.settle_s,
            measure_s: s.spec.hit.measure_s,
        }
    }

    #[test]
    fn soft_wall_rests_at_push_over_k() {
        // Linear scene, K = 1000 N/m, B = 20: the handle comes to rest where the
        // wall balances the push: y = push/K = 0.3572 mm past the wall.
        let spec = SceneSpec::from_json(r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#).unwrap();
        let sc = spec.validate().unwrap();
        let mut trace = Vec::new();
        let o = wall_hit(&sc, 1000.0, 20.0, knobs(&sc), &mut trace);
        assert!(o.stable, "{o:?}");
        assert!((o.mean_position - 0.3572 / 1000.0).abs() < 1e-9, "{o:?}");
        assert_eq!(trace.len(), o.samples);
        // One row per sample, at t = i·T.
        assert_eq!(trace[250].t, 250.0 * sc.dt);
        // Free flight before contact: m ẍ + b ẋ = push; the handle reaches the wall.
        assert!(trace.iter().any(|r| r.y > 0.0));
    }

    #[test]
    fn the_wall_can_stand_anywhere() {
        // The same soft wall (K = 1000 N/m, B = 20) at x = 0.05 m: the
        // handle rests push/K past it, at 0.05 + 0.3572e-3 m.
        let spec = SceneSpec::from_json(r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000},"wall":{"position":0.05}}"#).unwrap();
        let sc = spec.validate().unwrap();
        let o = wall_hit(&sc, 1000.0, 20.0, knobs(&sc), &mut NoTrace);
        assert!(o.stable, "{o:?}");
        assert!((o.mean_position - (0.05 + 0.3572e-3)).abs() < 1e-9, "{o:?}");
    }

    #[test]
    fn a_push_that_only_matches_friction_never_moves_the_handle() {
        // Push = Coulomb friction = 0.3572 N: no net drive, so the handle
        // stays home and the trial is settle + measure long (no wait for a
        // contact that cannot come).
        let spec = SceneSpec::from_json(
            r#"{"device":{"coulomb":0.3572,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
        )
        .unwrap();
        let sc = spec.validate().unwrap();
        assert_eq!(sc.spec.hit.push_force, 0.3572);
        let kn = HitKnobs {
            settle_s: 0.5,
            measure_s: 0.5,
        };
        let o = wall_hit(&sc, 1000.0, 20.0, kn, &mut NoTrace);
        assert_eq!(o.samples, 1000, "{o:?}");
        assert_eq!(o.mean_position, -sc.spec.hit.home_distance);
    }

    #[test]
    fn a_push_below_static_friction_is_waited_for() {
        // LuGre friction with F_s = 0.5 N above the 0.3572 N push above
        // F_c = 0.19 N: a step push breaks the handle loose anyway
        // (friction_tests.rs, the same device), so the trial waits for the
        // contact and measures the handle resting in the wall (push/K less
        // the friction band), not the approach.
        let spec = SceneSpec::from_json(
            r#"{"device":{"coulomb":0.19,"quantization":0,"friction":{"static":0.5}},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
        )
        .unwrap();
        let sc = spec.validate().unwrap();
        let kn = HitKnobs {
            settle_s: 0.5,
            measure_s: 0.5,
        };
        let o = wall_hit(&sc, 1000.0, 20.0, kn, &mut NoTrace);
        assert!(o.samples > 1000 && o.stable, "{o:?}");
        let (lo, hi) = ((0.3572 - 0.5) / 1000.0, (0.3572 + 0.5) / 1000.0);
        assert!(o.mean_position > lo && o.mean_position < hi, "{o:?}");
    }

    #[test]
    fn friction_hold_shortcut_gives_the_full_length_verdict() {
        // The seed device (Coulomb 0.19 N, 1 µm at 10 kHz, render 1 kHz):
        // where friction holds the handle, the trial ends early and counts
        // the rest of the window as the held position. The same trial run
        // to its end must give the same verdict, mean and RMS. With the
        // scene's 4 s settle the hold begins before the window; with a
        // 20 ms settle the window sees motion first (RMS > 0), so the held
        // samples merge into a window that already has a spread.
        let sc = SceneSpec::default().validate().unwrap();
        let short = HitKnobs {
            settle_s: 0.02,
            measure_s: 1.0,
        };
        let (mut shortened, mut merged) = (0, 0);
        for kn in [knobs(&sc), short] {
            for (k, b) in [
                (2e3, 0.0),
                (2e3, 30.0),
                (2e4, 5.0),
                (2e4, 60.0),
                (2e5, 15.0),
                (1e6, 100.0),
            ] {
                let mut rows = Vec::new();
                let early = wall_hit(&sc, k, b, kn, &mut rows);
                // `samples` counts the steps simulated, one trace row each.
                assert_eq!(rows.len(), early.samples, "K={k} B={b}");
                let full = run::<true, true, false>(
                    &sc,
                    k,
                    b,
                    kn,
                    sc.spec.hit.home_distance,
                    &mut NoTrace,
                );
                assert_eq!(early.stable, full.stable, "K={k} B={b}");
                assert_eq!(early.diverged, full.diverged, "K={k} B={b}");
                let (re, rf) = (early.rms.unwrap(), full.rms.unwrap());
                assert!(
                    (re - rf).abs() <= 1e-9 * rf.max(1e-9),
                    "K={k} B={b} {kn:?}: {re} vs {rf}"
                );
                assert!(
                    (early.mean_position - full.mean_position).abs() <= 1e-12,
                    "K={k} B={b}"
                );
                if early.samples < full.samples {
                    shortened += 1;
                    merged += usize::from(re > 0.0);
                }
            }
        }
        // The shortcut was taken (else this test checks nothing), also
        // after motion inside the window.
        assert!(shortened >= 2, "{shortened} trials ended early");
        assert!(
            merged >= 1,
            "{merged} ended early after motion in the window"
        );
    }

    #[test]
    fn a_diverging_hit_counts_the_steps_it_simulated() {
        // A 1 g handle without damping against K = 1e7 N/m at the seed's
        // 1 kHz render: 2b/T-style bounds (Colgate & Schenkel 1994) allow
        // no K at b = 0, and the wall's period (2π√(m/K) = 63 µs) is far
        // below the 100 µs encoder step: the handle's speed passes the
        // 1e3 m/s divergence bound within a few renders. `samples` is the
        // number of steps simulated, one trace row each.
        let j =
            r#"{"device":{"mass":0.001,"damping":0,"coulomb":0},"hit":{"home_distance":0.0001}}"#;
        let sc = SceneSpec::from_json(j).unwrap().validate().unwrap();
        let mut rows = Vec::new();
        let o = wall_hit(&sc, 1e7, 0.0, knobs(&sc), &mut rows);
        assert!(o.diverged && !o.stable && o.rms.is_none(), "{o:?}");
        assert_eq!(rows.len(), o.samples);
    }

    #[test]
    fn a_heavy_undamped_handle_is_waited_for_until_it_touches() {
        // No damping, no friction: free flight under the push is
        // x(t) = x0 + F·t²/(2m) (exact under a zero-order hold), so the
        // handle reaches the wall after √(2·d·m/F) = √(2·0.07·100/0.01)
        // = 37.4 s. Measurement starts `settle` after that contact, and the
        // trial is contact + settle + measure samples long.
        let spec = SceneSpec::from_json(
            r#"{"device":{"mass":100,"damping":0,"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000},"hit":{"push_force":0.01}}"#,
        )
        .unwrap();
        let sc = spec.validate().unwrap();
        let kn = HitKnobs {
            settle_s: 0.5,
            measure_s: 0.5,
        };
        let mut rows = Vec::new();
        let o = wall_hit(&sc, 1000.0, 20.0, kn, &mut rows);
        let h = &sc.spec.hit;
        let t_c = (2.0 * h.home_distance * 100.0 / h.push_force).sqrt();
        let contact = rows.iter().position(|r| r.y > 0.0).unwrap();
        assert!(
            (contact as f64 * 1e-3 - t_c).abs() <= 2e-3,
            "contact at {contact} samples, {t_c} s by the formula"
        );
        assert_eq!(o.samples, contact + 500 + 500, "{o:?}");
    }

    #[test]
    fn friction_without_quantization_rests_inside_the_friction_band() {
        // Coulomb 0.19 N, an ideal encoder: the soft wall (K = 1000 N/m,
        // B = 20) stops the handle where the spring force is within f_c of
        // the push, |K·y − push| ≤ f_c, i.e. y within 0.19 mm of 0.3572 mm.
        let spec = SceneSpec::from_json(
            r#"{"device":{"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
        )
        .unwrap();
        let sc = spec.validate().unwrap();
        assert!(sc.spec.device.coulomb > 0.0 && sc.spec.device.quantization == 0.0);
        let o = wall_hit(&sc, 1000.0, 20.0, knobs(&sc), &mut NoTrace);
        assert!(o.stable, "{o:?}");
        let push = sc.spec.hit.push_force;
        assert!(
            (1000.0 * o.mean_position - push).abs() <= 0.19 + 1e-9,
            "{o:?}"
        );
        // Friction moves the rest point off the frictionless one (push/K),
        // by less than f_c/K: it is not the linear loop in disguise.
        assert!((o.mean_position - push / 1000.0).abs() > 1e-7, "{o:?}");
    }

    #[test]
    fn far_beyond_colgate_is_unstable() {
        // FDM, B = 0, single rate 1 kHz: K = 10·2b/T is far past K = 2b/T.
        // The wall is unilateral, so the handle bounces (a limit cycle)
        // rather than diverging.
        let spec = SceneSpec::from_json(r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#).unwrap();
        let sc = spec.validate().unwrap();
        let o = wall_hit(&sc, 10.0 * 2.0 * 13.2 / 1e-3, 0.0, knobs(&sc), &mut NoTrace);
        assert!(!o.stable, "{o:?}");
        assert!(o.rms.unwrap() > 1e-5, "{o:?}");
    }

    /// A scene at 1 kHz from its device and hit JSON.
    fn scene_1khz(device: &str, hit: &str) -> Scene {
        SceneSpec::from_json(&format!(
            r#"{{"device":{device},"loop":{{"sample_hz":1000,"render_hz":1000}},"hit":{hit}}}"#
        ))
        .unwrap()
        .validate()
        .unwrap()
    }

    #[test]
    fn replicate_r_starts_r_over_r_of_an_encoder_step_farther() {
        // hit.replicates = 4 on a 2 µm encoder: replicate 3 starts 1.5 µm
        // farther from the wall than the scene's home; with an ideal sensor
        // the step is 1 µm. Replicate 0 is the plain hit.
        let rows = |device: &str, r: u32| {
            let sc = scene_1khz(
                device,
                r#"{"replicates":4,"settle_s":0.01,"measure_s":0.01}"#,
            );
            let kn = HitKnobs {
                settle_s: 0.01,
                measure_s: 0.01,
            };
            let mut t: Vec<TraceRow> = Vec::new();
            replicate_hit(&sc, 1000.0, 0.0, kn, r, &mut t);
            (t[0].x, sc.spec.hit.home_distance)
        };
        let (x, home) = rows(r#"{"quantization":2e-6}"#, 3);
        assert_eq!(x, -(home + 1.5e-6));
        let (x, home) = rows(r#"{"quantization":0}"#, 1);
        assert_eq!(x, -(home + 0.25e-6));
        let (x, home) = rows(r#"{"quantization":2e-6}"#, 0);
        assert_eq!(x, -home);
        // The verdict of R hits: the majority, a tie unstable, decided
        // only when all agree.
        let v = |hits, stable| Replicated {
            hits,
            stable,
            saturated: false,
        };
        assert!(v(3, 2).stable() && !v(3, 1).stable() && !v(2, 1).stable() && v(2, 2).stable());
        assert!(v(3, 3).decided() && v(3, 0).decided() && !v(3, 2).decided() && !v(3, 1).decided());
    }

    #[test]
    fn the_wait_for_contact_is_capped_at_ten_approach_times_plus_a_second() {
        let half = HitKnobs {
            settle_s: 0.5,
            measure_s: 0.5,
        };
        // Damped: the estimate is d·b/F + m/b (terminal velocity plus its
        // time constant) = 1e-6·100/0.03 + 0.52/100 = 8.5333 ms, so the cap
        // is ⌊(10·8.5333 ms + 1 s)/1 ms⌋ = 1085 samples. The 2 mm encoder
        // first reads past the wall at x ≥ 1 mm, ~3.3 s at F/b = 0.3 mm/s:
        // the cap binds, and the window that follows reads 0 throughout.
        let sc = scene_1khz(
            r#"{"mass":0.52,"damping":100,"coulomb":0,"quantization":0.002}"#,
            r#"{"push_force":0.03,"home_distance":1e-6}"#,
        );
        let o = wall_hit(&sc, 1000.0, 20.0, half, &mut NoTrace);
        assert_eq!(o.samples, 1085 + 500, "{o:?}");
        assert_eq!((o.mean_position, o.rms, o.stable), (0.0, Some(0.0), true));
        // Undamped: √(2·d·m/F) = √(2·1e-6·100/0.01) = 0.14142 s: cap
        // ⌊(1.4142 + 1)/1 ms⌋ = 2414 (contact only at √(2·1 mm/1e-4) ≈ 4.5 s).
        let sc = scene_1khz(
            r#"{"mass":100,"damping":0,"coulomb":0,"quantization":0.002}"#,
            r#"{"push_force":0.01,"home_distance":1e-6}"#,
        );
        let o = wall_hit(&sc, 1000.0, 20.0, half, &mut NoTrace);
        assert_eq!(o.samples, 2414 + 500, "{o:?}");
    }

    #[test]
    fn the_window_is_settle_after_contact_and_its_rms_is_about_its_mean() {
        // 2011 paper §2.4: RMS of the measured position about its mean over
        // the window. Recomputed here in two passes from the trace.
        let sc = scene_1khz(r#"{"coulomb":0,"quantization":0}"#, "{}");
        let kn = HitKnobs {
            settle_s: 0.02,
            measure_s: 0.2,
        };
        let mut trace = Vec::new();
        let o = wall_hit(&sc, 1000.0, 20.0, kn, &mut trace);
        let c = trace.iter().position(|r| r.y > 0.0).unwrap();
        assert_eq!(o.samples, c + 20 + 200);
        let w: Vec<f64> = trace[c + 20..c + 220].iter().map(|r| r.y).collect();
        let mean = w.iter().sum::<f64>() / 200.0;
        let rms = (w.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / 200.0).sqrt();
        assert!(
            (o.mean_position - mean).abs() <= 1e-12 * mean.abs(),
            "{o:?} vs {mean}"
        );
        let got = o.rms.unwrap();
        assert!(
            rms > 1e-6 && (got - rms).abs() <= 1e-9 * rms,
            "{got} vs {rms}"
        );
    }

    #[test]
    fn a_trial_diverges_on_position_alone() {
        // No damping, no wall (K = B = 0): free flight at F/m from 7 cm
        // before the wall; x = 10 m at t = √(2·10.07·0.52/0.3572) = 5.4148 s,
        // where v = 3.7 m/s is far below the velocity bound.
        let sc = scene_1khz(r#"{"damping":0,"coulomb":0,"quantization":0}"#, "{}");
        let o = wall_hit(&sc, 0.0, 0.0, knobs(&sc), &mut NoTrace);
        assert!(o.diverged && !o.stable && o.rms.is_none(), "{o:?}");
        assert!((5414..=5416).contains(&o.samples), "{o:?}");
    }

    #[test]
    fn a_held_handle_ends_the_trial_after_exactly_two_tenths_of_a_second() {
        // The seed device (10 kHz): the shortcut takes ⌈0.2 s / 0.1 ms⌉ =
        // 2000 held samples, the last of them the trial's last: the trace's
        // final 2000 rows read one position, the row before another (or the
        // hold would have ended the trial sooner).
        let sc = SceneSpec::default().validate().unwrap();
        let mut trace = Vec::new();
        let o = wall_hit(&sc, 2e3, 30.0, knobs(&sc), &mut trace);
        let total = ((knobs(&sc).settle_s + knobs(&sc).measure_s) / sc.dt).round() as usize;
        assert!(o.samples < total, "the hold ended it early: {o:?}");
        assert_eq!(trace.len(), o.samples);
        let tail = &trace[o.samples - 2000..];
        assert!(tail.iter().all(|r| r.y == tail[0].y), "one position");
        let before = &trace[..o.samples - 2000];
        assert!(
            before
                .iter()
                .rev()
                .take(2000)
                .any(|r| r.y != tail[0].y || r.v != 0.0),
            "held for more than 0.2 s before the end"
        );
    }

    #[test]
    fn with_a_transmission_the_wait_counts_both_masses() {
        // A 1e4 kg motor side behind a 1 N/m cable, the 0.3 kg handle
        // 1e-4 m from the wall, encoder on the handle, 1 kHz: the push
        // (0.3572 N) drags both masses; the estimate d·(b + b_m)/F +
        // (m + m_m)/(b + b_m) = 3.7e-3 + 757.6 s sets the wait, so the trial
        // measures after the contact (the soft cable makes the handle
        // trail the motor: ~6 s), not at home. The handle alone would give
        // 1e-4·13.2/0.3572 + 0.3/13.2 = 26.4 ms: a cap of ⌊(0.264 + 1)/1 ms⌋
        // = 1263 samples, before the contact.
        let sc = scene_1khz(
            r#"{"mass":0.3,"coulomb":0,"quantization":0,"transmission":{"motor_mass":1e4,"stiffness":1,"encoder":"handle"}}"#,
            r#"{"home_distance":1e-4}"#,
        );
        let kn = HitKnobs {
            settle_s: 0.05,
            measure_s: 0.02,
        };
        let mut trace = Vec::new();
        let o = wall_hit(&sc, 1000.0, 20.0, kn, &mut trace);
        let c = trace.iter().position(|r| r.y > 0.0).expect("contact");
        assert!(c > 1263, "contact at sample {c}");
        assert_eq!(o.samples, c + 50 + 20);
    }
}
