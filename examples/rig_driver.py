#!/usr/bin/env python3
"""A rig driver for `zwidth agent --driver "python3 examples/rig_driver.py"`.

The agent writes one JSON object per line on our stdin and reads one per
line from our stdout (docs/rigs.md, "the driver protocol"):
  {"type":"capabilities"}            -> {"type":"capabilities", ...}
  {"type":"trial","request":…,"limits":…} -> {"type":"result","point":…,"measured":…}
                                        or {"type":"error","message":…}
  {"type":"abort"}                   -> (no answer: end the running trial early,
                                        answering it with an error)
Replace `wall_hit` with your controller's (QuaRC, a microcontroller bridge…).
Here it is a toy device: a mass with viscous and Coulomb friction, an
encoder of 1 µm, the trial's own velocity estimator, one sample of
computation delay, the wall
F = -K x - B v̂ for x > 0 (2011 paper §2.4: push into the wall, settle,
then judge the last seconds), the force clamped to the trial's limit.

The estimator is zwidth's own through the Python package (`pip install
./python`, README "The estimators outside Rust"): every kind, bit for bit
as the simulator, and the capabilities say so (`dsp`). Without the package
the script falls back to a backward difference of its own and advertises
`fdm` only (and no `dsp`: the server then warns that the rig's estimators
are not known to be its own).
"""
import json
import math
import sys

try:
    import zwidth
except ImportError:  # the package is not installed: FDM of our own
    zwidth = None

CAPS = {"peak_force_n": 10.0, "continuous_force_n": 4.0, "k_max": 1e6, "b_max": 1e4,
        "travel_m": 0.1, "speed_m_s": 1.0, "encoder_m": 1e-6,
        "sample_hz": [1000.0, 2000.0], "estimators": ["fdm"], "probes": ["wall_hit"]}
if zwidth is not None:
    CAPS.update(estimators=["fdm", "butterworth", "kalman", "adaptive_kalman", "foaw", "levant"],
                dsp=zwidth.dsp_identity())


class BackwardDifference:
    """(y_k - y_{k-1}) / T (2011 paper eq. 2): the fallback estimator."""

    def __init__(self, rate_hz):
        self.T, self.prev = 1.0 / rate_hz, None

    def step(self, y):
        v = 0.0 if self.prev is None else (y - self.prev) / self.T
        self.prev = y
        return v


def estimator(scene, rate_hz, q):
    """The trial's estimator: the scene's spec through zwidth, else FDM."""
    if zwidth is None:
        return BackwardDifference(rate_hz)
    return zwidth.Estimator(scene.get("estimator", {"kind": "fdm"}), rate_hz, q)


def wall_hit(req, limits):
    dev, loop = req["scene"]["device"], req["scene"]["loop"]
    m, b, fc = dev["mass"], dev["damping"], dev.get("coulomb", 0.0)
    T, K, B = 1.0 / loop["sample_hz"], req["k"], req["b"]
    f_max, q = limits["force_limit_n"], dev.get("quantization", 1e-6)
    est = estimator(req["scene"], loop["sample_hz"], q)
    push = 0.36                                   # N, toward the wall
    x, v = -0.002, 0.0                            # m, m/s
    f_out = 0.0                                   # N, applied one sample late
    peak_f = peak_v = depth = 0.0
    settle, measure = int(4.0 / T), int(2.0 / T)
    lo, hi = math.inf, -math.inf
    for n in range(settle + measure):
        y = round(x / q) * q                      # the encoder
        v_hat = est.step(y)                       # the trial's estimator
        f = -K * y - B * v_hat if y > 0 else 0.0  # the virtual wall
        f = max(-f_max, min(f_max, f))            # the controller's clamp
        f, f_out = f_out, f                       # one sample of computation delay
        if abs(x) > limits["abort_penetration_m"] or abs(v) > limits["abort_speed_m_s"]:
            return None, {"peak_force_n": peak_f, "peak_speed_m_s": peak_v, "penetration_m": depth}
        a = (push + f - b * v - fc * math.copysign(1.0, v) * (v != 0)) / m
        v += a * T
        x += v * T
        peak_f, peak_v, depth = max(peak_f, abs(f)), max(peak_v, abs(v)), max(depth, x)
        if n >= settle:
            lo, hi = min(lo, y), max(hi, y)
    stable = hi - lo <= 2 * q                     # still within 2 counts
    return stable, {"peak_force_n": peak_f, "peak_speed_m_s": peak_v, "penetration_m": depth}


for line in sys.stdin:
    msg = json.loads(line)
    if msg["type"] == "capabilities":
        out = dict(CAPS, type="capabilities")
    elif msg["type"] == "trial":
        req = msg["request"]
        try:
            stable, measured = wall_hit(req, msg["limits"])
        except ValueError as e:  # the estimator refused its spec, naming the field
            print(json.dumps({"type": "error", "message": f"estimator: {e}"}), flush=True)
            continue
        if stable is None:
            out = {"type": "error", "message": "aborted: past the speed or travel limit"}
        else:
            out = {"type": "result", "point": {"k": req["k"], "b": req["b"], "stable": stable},
                   "measured": measured}
    else:
        # An abort: this toy runs each trial to its end before it reads the
        # next line, so there is nothing left to abort. A real driver
        # watches stdin during a trial, ramps the force down and answers
        # the trial with {"type":"error","message":"aborted"}.
        continue
    print(json.dumps(out), flush=True)
