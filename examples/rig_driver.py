#!/usr/bin/env python3
"""A rig driver for `zwidth agent --driver "python3 examples/rig_driver.py"`.

The agent writes one JSON object per line on our stdin and reads one per
line from our stdout (docs/rigs.md, "the driver protocol"):
  {"type":"capabilities"}            -> {"type":"capabilities", ...}
  {"type":"trial","request":…,"limits":…} -> {"type":"result","point":…,"measured":…}
                                        or {"type":"error","message":…}
  {"type":"abort"}                   -> (no answer of its own: the running trial
                                        stops and is answered {"type":"error",
                                        "message":"aborted"}; between trials it
                                        is ignored)
Replace `wall_hit` with your controller's (QuaRC, a microcontroller bridge…).
Here it is a toy device: a mass with viscous and Coulomb friction, an
encoder of 1 µm, the trial's own velocity estimator, one sample of
computation delay, the wall
F = -K x - B v̂ for x > 0 (2011 paper §2.4: push into the wall, settle,
then judge the last seconds), the force clamped to the trial's limit.
During a trial the driver watches stdin every 10 ms of the device's time
for an abort, as a real controller must (ramp the force down, answer).
`--realtime` paces the toy like hardware: each sample waits for its time,
so a trial takes its 6 s (what the abort test uses).

The estimator is zwidth's own through the Python package (`pip install
./python`, README "The estimators outside Rust"): every kind, bit for bit
as the simulator, and the capabilities say so (`dsp`). Without the package
the script falls back to a backward difference of its own and advertises
`fdm` only (and no `dsp`: the server then warns that the rig's estimators
are not known to be its own).
"""
import json
import math
import os
import select
import sys
import time

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


class Lines:
    """Lines from the agent on fd 0, read without blocking a trial:
    `next()` waits for one (None at the end), `abort_waiting()` says
    whether an abort has arrived since (and takes it)."""

    def __init__(self, fd=0):
        self.fd, self.buf, self.eof = fd, b"", False

    def _fill(self, timeout):
        if self.eof:
            return
        ready, _, _ = select.select([self.fd], [], [], timeout)
        if ready:
            chunk = os.read(self.fd, 65536)
            self.buf += chunk
            self.eof = not chunk

    def next(self):
        while b"\n" not in self.buf and not self.eof:
            self._fill(None)
        if b"\n" not in self.buf:
            return None
        line, self.buf = self.buf.split(b"\n", 1)
        return line.decode()

    def abort_waiting(self):
        self._fill(0)
        if b"\n" not in self.buf:
            return False
        first = self.buf.split(b"\n", 1)[0]
        try:
            is_abort = json.loads(first).get("type") == "abort"
        except ValueError:
            return False
        if is_abort:
            self.buf = self.buf.split(b"\n", 1)[1]
        return is_abort


class Aborted(Exception):
    """The agent asked the running trial to stop."""


REALTIME = "--realtime" in sys.argv[1:]


def wall_hit(req, limits, lines):
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
    every = max(1, int(0.01 / T))                 # samples in 10 ms
    start = time.monotonic()
    for n in range(settle + measure):
        if n % every == 0:
            if REALTIME:                          # hardware's pace
                time.sleep(max(0.0, start + n * T - time.monotonic()))
            if lines.abort_waiting():
                raise Aborted()
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


if any(a != "--realtime" for a in sys.argv[1:]):
    sys.exit(f"usage: {sys.argv[0]} [--realtime]")
lines = Lines()
while (line := lines.next()) is not None:
    if not line.strip():
        continue
    msg = json.loads(line)
    if msg["type"] == "capabilities":
        out = dict(CAPS, type="capabilities")
    elif msg["type"] == "trial":
        req = msg["request"]
        try:
            stable, measured = wall_hit(req, msg["limits"], lines)
        except ValueError as e:  # the estimator refused its spec, naming the field
            print(json.dumps({"type": "error", "message": f"estimator: {e}"}), flush=True)
            continue
        except Aborted:  # a real driver ramps its force down here
            print(json.dumps({"type": "error", "message": "aborted"}), flush=True)
            continue
        if stable is None:
            out = {"type": "error", "message": "aborted: past the speed or travel limit"}
        else:
            out = {"type": "result", "point": {"k": req["k"], "b": req["b"], "stable": stable},
                   "measured": measured}
    else:
        # An abort between trials: nothing is running.
        continue
    print(json.dumps(out), flush=True)
