"""examples/rig_driver.py with the package installed: it advertises every
estimator kind and this library's identity, and a trial runs the scene's
own estimator (a bad spec comes back as the driver protocol's error naming
the field, never a crash)."""

import json
import pathlib
import subprocess
import sys

import zwidth

DRIVER = pathlib.Path(__file__).resolve().parents[2] / "examples/rig_driver.py"

SCENE = {
    "device": {"mass": 0.1, "damping": 0.0, "coulomb": 0.05, "quantization": 1e-6},
    "loop": {"sample_hz": 1000.0},
}
LIMITS = {"force_limit_n": 8.0, "abort_speed_m_s": 1.0, "abort_penetration_m": 0.01}


def talk(messages):
    """Each message on a line of the driver's stdin; its answer lines."""
    text = "".join(json.dumps(m) + "\n" for m in messages)
    out = subprocess.run([sys.executable, str(DRIVER)], input=text, capture_output=True,
                         text=True, timeout=120, check=True)
    return [json.loads(line) for line in out.stdout.splitlines()]


def trial(k, b, estimator):
    return {"type": "trial", "limits": LIMITS,
            "request": {"k": k, "b": b, "scene": dict(SCENE, estimator=estimator)}}


def test_it_advertises_every_kind_and_the_librarys_identity():
    (caps,) = talk([{"type": "capabilities"}])
    assert caps["type"] == "capabilities"
    assert caps["estimators"] == ["fdm", "butterworth", "kalman", "adaptive_kalman", "foaw",
                                  "levant"]
    assert caps["dsp"] == zwidth.dsp_identity()
    assert sorted(caps["dsp"]["fingerprints"]) == sorted(caps["estimators"])
    assert all(len(p) == 16 for p in caps["dsp"]["fingerprints"].values())


def test_a_trial_runs_the_scenes_estimator_and_a_bad_spec_is_an_error():
    soft = trial(1e3, 0.0, {"kind": "levant", "mu1": 1.06, "mu2": 0.65, "lipschitz": 20})
    bad = trial(1e3, 0.0, {"kind": "butterworth", "cutoff_hz": 600})  # beyond Nyquist at 1 kHz
    ok, refused = talk([soft, bad])
    assert ok["type"] == "result", ok
    assert ok["point"] == {"k": 1e3, "b": 0.0, "stable": ok["point"]["stable"]}
    assert ok["measured"]["penetration_m"] > 0
    assert refused["type"] == "error"
    assert "cutoff_hz" in refused["message"], refused
