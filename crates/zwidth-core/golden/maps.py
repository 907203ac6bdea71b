#!/usr/bin/env python3
"""Writes maps.json: small maps of every example scene, each trial as the
`zwidth map --json` of a given binary printed it. The file pins the engines'
output bit for bit (tests/it/bit_identical.rs): a speed-up that keeps the
arithmetic must leave it unchanged.

Written by the build of main at 2595a59 (before issue 34's changes), and
re-recorded once for issue 44 (2026-12-06) after the BLA verdict began to
call a wall that clips at the force limit not passive (bla.rs, `clipped`):
only the two frequency-domain cases with a force limit changed (two_mass,
mode_lag); the other ten are as 2595a59 wrote them.
    python3 crates/zwidth-core/golden/maps.py path/to/zwidth > crates/zwidth-core/golden/maps.json
"""
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

# (name, scene file, method, criterion, accuracy, B values): every example
# scene, each engine it runs on, a column or two, draft where that is enough.
CASES = [
    ("seed_2018 frequency draft", "seed_2018.json", "frequency", "impedance", "draft", [0, 400]),
    ("seed_2018 frequency standard", "seed_2018.json", "frequency", "impedance", "standard", [600]),
    ("seed_2018_levant frequency draft", "seed_2018_levant.json", "frequency", "impedance", "draft", [0]),
    ("seed_2011 time draft", "seed_2011.json", "time", "stability", "draft", [0, 300]),
    ("linear_1khz analytic standard", "linear_1khz.json", "analytic", "impedance", "standard", [0, 300]),
    ("linear_1khz time draft", "linear_1khz.json", "time", "stability", "draft", [0, 300]),
    ("linear_1khz frequency draft", "linear_1khz.json", "frequency", "impedance", "draft", [300]),
    ("two_mass frequency draft", "two_mass_motor_encoder.json", "frequency", "impedance", "draft", [300]),
    ("two_mass time draft", "two_mass_motor_encoder.json", "time", "stability", "draft", [300]),
    ("mode_lag frequency draft", "mode_lag_2011.json", "frequency", "impedance", "draft", [1]),
    ("mode_lag time draft", "mode_lag_2011.json", "time", "stability", "draft", [1]),
    ("rig_2011 time draft", "rig_2011_motor_encoder.json", "time", "stability", "draft", [300]),
]


def main():
    binary = sys.argv[1]
    out = []
    for name, scene, method, criterion, accuracy, bs in CASES:
        path = ROOT / "examples" / scene
        args = [binary, "map", "--scene", str(path), "--method", method,
                "--criterion", criterion, "--accuracy", accuracy, "--json",
                "--b", ",".join(str(b) for b in bs)]
        r = json.loads(subprocess.run(args, check=True, capture_output=True).stdout)
        out.append({
            "name": name,
            "spec": {
                "scene": json.loads(path.read_text()),
                "method": method,
                "criterion": criterion,
                "accuracy": accuracy,
                "b": [float(b) for b in bs],
            },
            "boundary": r["boundary"],
            "points": r["points"],
        })
    json.dump(out, sys.stdout, indent=1)
    print()


main()
