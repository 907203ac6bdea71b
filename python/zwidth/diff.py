"""Differentiation shaped like PyNumDiff's methods:
`x_hat, dxdt_hat = zwidth.diff.<kind>(x, dt, **params)`, one function per
estimator kind (fdm, butterworth, kalman, adaptive_kalman, foaw, levant),
its parameters the API's estimator spec's (`docs/estimators.md`), e.g.
`zwidth.diff.butterworth(x, 1e-3, cutoff_hz=100, order=2)`.

Unlike PyNumDiff's smoothers these are **causal**: sample i's velocity uses
samples up to i only, as a haptic controller must; they estimate velocity
only, so `x_hat` is `x` itself (a copy), in m, and `dxdt_hat` in m/s, bit
for bit what `zwidth.Estimator(...).run(x)` and a rig return.
`quantization` is the encoder step (m) the estimators are built for (FOAW's
band, Kalman's measurement noise): the default 1e-9 m is the ideal sensor's
(as a scene with `quantization: 0`).
"""

from __future__ import annotations

import math
from typing import Any, Callable, Tuple

from ._arrays import positions
from ._zwidth import Estimator

__all__ = ["KINDS", "fdm", "butterworth", "kalman", "adaptive_kalman", "foaw", "levant"]

#: The estimator kinds, one function each.
KINDS = ("fdm", "butterworth", "kalman", "adaptive_kalman", "foaw", "levant")


def _method(kind: str) -> Callable[..., Tuple[Any, Any]]:
    def differentiate(x: Any, dt: float, *, quantization: float = 1e-9, **params: Any):
        try:
            ok = math.isfinite(float(dt)) and float(dt) > 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise ValueError(f"dt = {dt} is not allowed: must be a finite number > 0 (s)")
        xs = positions("x", x)
        e = Estimator({"kind": kind, **params}, 1.0 / float(dt), quantization)
        return xs.copy(), e.run(xs)

    differentiate.__name__ = differentiate.__qualname__ = kind
    differentiate.__doc__ = (
        f"`x_hat, dxdt_hat` of positions `x` (m) sampled every `dt` s by the causal "
        f"`{kind}` estimator; `params` are its spec's fields (docs/estimators.md)."
    )
    return differentiate


fdm = _method("fdm")
butterworth = _method("butterworth")
kalman = _method("kalman")
adaptive_kalman = _method("adaptive_kalman")
foaw = _method("foaw")
levant = _method("levant")
