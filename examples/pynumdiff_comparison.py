"""zwidth's causal estimators beside PyNumDiff's differentiators on one
signal (docs/python.md, "Beside PyNumDiff"). Run: `pip install ./python
pynumdiff && python3 examples/pynumdiff_comparison.py`.

The signal: x = 1 mm·sin(2π·2 t) sampled at 1 kHz for 2 s through a 1 µm
encoder (quantized); the true velocity is 4π mm/s·cos(2π·2 t). Errors are
RMS over 0.2–1.8 s (away from both ends, which PyNumDiff's non-causal
smoothers see from both sides), relative to the velocity's amplitude.
"""

import warnings

import numpy as np

import zwidth

warnings.filterwarnings("ignore")  # PyNumDiff warns that CVXPY is missing
import pynumdiff.finite_difference as pfd  # noqa: E402
import pynumdiff.smooth_finite_difference as psfd  # noqa: E402

dt, q = 1e-3, 1e-6
t = np.arange(2000) * dt
x = np.round(1e-3 * np.sin(2 * np.pi * 2 * t) / q) * q
v_true = 4e-3 * np.pi * np.cos(2 * np.pi * 2 * t)
inner = (t >= 0.2) & (t <= 1.8)


def rms(v):
    return np.sqrt(np.mean((v[inner] - v_true[inner]) ** 2)) / (4e-3 * np.pi)


rows = [
    ("pynumdiff finitediff (central, non-causal)", pfd.finitediff(x, dt)[1]),
    ("pynumdiff butterdiff 50 Hz, order 2 (zero-phase, non-causal)",
     psfd.butterdiff(x, dt, filter_order=2, cutoff_freq=0.1)[1]),
    ("zwidth fdm (backward difference, causal)", zwidth.diff.fdm(x, dt, quantization=q)[1]),
    ("zwidth butterworth 50 Hz, order 2 (causal)",
     zwidth.diff.butterworth(x, dt, quantization=q, cutoff_hz=50, order=2)[1]),
    ("zwidth kalman q = 1e4 (causal)", zwidth.diff.kalman(x, dt, quantization=q, q=1e4)[1]),
    ("zwidth foaw best-fit, d = 1 µm (causal)",
     zwidth.diff.foaw(x, dt, quantization=q, fit="best", d=q, max_window=15)[1]),
]
print(f"{'method':62} {'RMS error':>10}")
for name, v in rows:
    print(f"{name:62} {100 * rms(v):9.2f} %")
