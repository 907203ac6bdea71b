//! When a noisy scene's rendered wall escapes: the realization in which the
//! frequency engine's loop diverged, at each K of one B column, for
//! independent probe seeds (docs/zwidth.md, "The seed device's boundary is
//! an escape hazard"). A measurement for the search's design, not a map.
//!
//! cargo run --release -p zwidth-core --example escape_times -- \
//!     examples/seed_2018.json 238.08 48 20 380000,395000,410000,420000
//!
//! Arguments: scene file, B (N·s/m), the most realizations per trial, the
//! number of seeds (1..=seeds), K values (N/m, comma-separated). Each row:
//! K, then per seed the realization that escaped, or `P` (decided passive
//! and stopped), `.` (no escape, undecided passive), `-` (no escape,
//! undecided not passive), `N` (decided not passive without escaping);
//! then escapes / seeds and the realizations run in all (the exposure):
//! escapes / exposure is the escape hazard per realization (1/realization).

use zwidth_core::zwidth::probe::{probe, ProbeKnobs};
use zwidth_core::zwidth::SceneSpec;

fn usage(why: &str) -> ! {
    eprintln!(
        "escape_times: {why}\nusage: escape_times SCENE.json B MAX_REALIZATIONS SEEDS K1,K2,…"
    );
    std::process::exit(2)
}

fn number<T: std::str::FromStr>(what: &str, s: &str) -> T {
    s.parse()
        .unwrap_or_else(|_| usage(&format!("{what} = {s:?} is not a number")))
}

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let [path, b, cap, seeds, ks] = a.as_slice() else {
        usage("five arguments")
    };
    let b: f64 = number("B", b);
    let cap: u32 = number("MAX_REALIZATIONS", cap);
    let seeds: u64 = number("SEEDS", seeds);
    let ks: Vec<f64> = ks.split(',').map(|s| number("K", s)).collect();
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| usage(&format!("{path}: {e}")));
    let spec: SceneSpec =
        serde_json::from_str(&text).unwrap_or_else(|e| usage(&format!("{path}: {e}")));
    // The standard preset's probe knobs, with the realization cap given.
    let knobs = ProbeKnobs {
        periods: spec.probe.periods,
        settle_tol: 1e-3,
        max_periods: 150,
        realizations: cap,
    };
    for &k in &ks {
        let mut row = format!("{k:9.0}");
        let (mut escapes, mut exposure) = (0, 0u32);
        for seed in 1..=seeds {
            let mut s = spec.clone();
            s.probe.seed = seed;
            let scene = s.validate().unwrap_or_else(|e| usage(&e.to_string()));
            let o = probe(&scene, k, b, knobs);
            let Some(c) = o.confidence else {
                usage("the scene is not noisy (no friction or quantization): nothing escapes at random")
            };
            exposure += c.realizations;
            row += &match (o.diverged, c.decided, o.passive) {
                (true, ..) => {
                    escapes += 1;
                    format!(" {:>3}", c.realizations)
                }
                (false, true, true) => "   P".into(),
                (false, true, false) => "   N".into(),
                (false, false, true) => "   .".into(),
                (false, false, false) => "   -".into(),
            };
        }
        println!("{row}   escapes {escapes}/{seeds}, exposure {exposure} realizations");
    }
}
