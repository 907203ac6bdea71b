//! Each replicate wall hit's own boundary, per B column: how far apart the
//! replicates of the rig's protocol put it, and whether one replicate's
//! verdict is monotone in K (docs/zwidth.md, "The rig's replicate hits").
//! A measurement for the search's design, not a map.
//!
//! cargo run --release -p zwidth-core --example replicate_spread -- \
//!     examples/rig_2011_motor_encoder.json 14.88 8
//!
//! Arguments: scene file (with `hit.replicates`), the B step (N·s/m) and
//! the number of columns from B = 0. Each replicate r (its hit starting r/R
//! of an encoder step farther from the wall, `hit::replicate_hit`) is
//! bracketed by doubling from 1 488.24 N/m (standard's K step on that
//! scene) and bisected to 0.05 %; then 0.3, 0.5, 0.7, 0.9, 0.95 and 0.98
//! of its boundary are hit again, and those that fail are listed (a
//! verdict monotone in K fails at none). Standard's hit: 4 s settle, 2 s
//! measure.

use zwidth_core::zwidth::hit::{replicate_hit, HitKnobs, NoTrace};
use zwidth_core::zwidth::SceneSpec;

fn usage(why: &str) -> ! {
    eprintln!("replicate_spread: {why}\nusage: replicate_spread SCENE.json B_STEP COLUMNS");
    std::process::exit(2)
}

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let [path, b_step, columns] = a.as_slice() else {
        usage("three arguments")
    };
    let b_step: f64 = b_step
        .parse()
        .unwrap_or_else(|_| usage("B_STEP is not a number"));
    let columns: u32 = columns
        .parse()
        .unwrap_or_else(|_| usage("COLUMNS is not a whole number"));
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| usage(&format!("{path}: {e}")));
    let spec: SceneSpec =
        serde_json::from_str(&text).unwrap_or_else(|e| usage(&format!("{path}: {e}")));
    let scene = spec.validate().unwrap_or_else(|e| usage(&e.to_string()));
    let knobs = HitKnobs {
        settle_s: 4.0,
        measure_s: 2.0,
    };
    const CHECKS: [f64; 6] = [0.3, 0.5, 0.7, 0.9, 0.95, 0.98];
    for j in 0..columns {
        let b = f64::from(j) * b_step;
        let mut row = format!("B {b:7.2} N·s/m:");
        for r in 0..spec.hit.replicates.max(1) {
            let stable = |k: f64| replicate_hit(&scene, k, b, knobs, r, &mut NoTrace).stable;
            let (mut lo, mut hi) = (0.0, 1488.24);
            while stable(hi) && hi < 1e7 {
                (lo, hi) = (hi, 2.0 * hi);
            }
            if lo == 0.0 {
                row += &format!("  r{r}: none from {hi}");
                continue;
            }
            while hi - lo > 5e-4 * hi {
                let m = 0.5 * (lo + hi);
                if stable(m) {
                    lo = m
                } else {
                    hi = m
                }
            }
            let fails: Vec<String> = CHECKS
                .iter()
                .filter(|&&f| !stable(f * lo))
                .map(|f| f.to_string())
                .collect();
            row += &format!("  r{r}: {lo:8.0} (fails at [{}])", fails.join(" "));
        }
        println!("{row}");
    }
}
