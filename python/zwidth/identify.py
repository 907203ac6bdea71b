"""Device identification from Python: record an open-loop trace of a
simulated device, and identify a device (m, b, f_c, a transmission mode)
from a trace, as `zwidth record` and `zwidth identify` do (docs/identify.md).

A trace is three evenly sampled columns: `t_s` (s), `force_n` (N, the force
command), `position_m` (m, the encoder): a pandas DataFrame or a dict with
those columns, an (n, 3) array in that order, or the path of the CSV `zwidth
record` writes. It crosses to the engine as that CSV, so its checks and
messages are the CLI's (`trace line 12, column 2 (force_n) = inf is not
allowed: …`; line 1 is the header, so row i of a DataFrame is line i + 2).
"""

from __future__ import annotations

import os

from . import _zwidth
from ._arrays import column_names
from .engines import _scene_text

TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, Dict, Optional

    from .engines import SceneLike

__all__ = ["COLUMNS", "Identification", "record", "identify"]

#: A trace's columns, in order.
COLUMNS = ("t_s", "force_n", "position_m")


def record(
    scene: SceneLike,
    *,
    period_s: float = 2.0,
    f_max_hz: float = 20.0,
    peak_force: float = 1.0,
    duration_s: float = 20.0,
    band: Optional[Dict[str, float]] = None,
) -> Dict[str, Any]:
    """An open-loop trace of `scene`'s device under a Schroeder multisine
    force (lines every 1/`period_s` Hz up to `f_max_hz`, peaking at
    `peak_force` N, for `duration_s` s; `band`: a second multisine
    `{"f_min_hz", "f_max_hz", "peak_force"}` around a transmission mode).
    A dict of numpy arrays `t_s`, `force_n`, `position_m`
    (`pandas.DataFrame(record(...))` makes a frame of it)."""
    import numpy as np

    ex: Dict[str, Any] = {"period_s": period_s, "f_max_hz": f_max_hz,
                          "peak_force": peak_force, "duration_s": duration_s}
    if band is not None:
        ex["band"] = band
    csv = _zwidth.record_csv(_scene_text(scene), _zwidth.dumps(ex, ""))
    # Python's float() reads each shortest round-trip number back exactly.
    rows = [tuple(map(float, line.split(","))) for line in csv.splitlines()[1:] if line]
    return {name: np.array([r[i] for r in rows]) for i, name in enumerate(COLUMNS)}


class Identification:
    """What `identify` found (`identified`: the JSON of `zwidth identify
    --json`, every estimate with its 95 % interval) and the scene it writes
    (`scene`: `zwidth identify --out`), ready for `zwidth.map(...)`."""

    def __init__(self, raw: Dict[str, Any]):
        self.identified: Dict[str, Any] = raw["identified"]
        self.scene: Dict[str, Any] = raw["scene"]
        self.mass: float = self.identified["mass"]["value"]
        self.damping: float = self.identified["damping"]["value"]
        self.coulomb: float = self.identified["coulomb"]["value"]

    def to_dict(self) -> Dict[str, Any]:
        return {"identified": self.identified, "scene": self.scene}

    def __repr__(self) -> str:
        return (f"Identification(model={self.identified['model']!r}, mass={self.mass:.5g} kg, "
                f"damping={self.damping:.5g} N·s/m, coulomb={self.coulomb:.5g} N)")


def identify(
    trace: Any,
    model: str = "mass_damper_coulomb",
    *,
    mode_trace: Any = None,
    scene: Optional[SceneLike] = None,
) -> Identification:
    """The device from `trace`: `model` mass_damper_coulomb | mass_damper |
    two_mass (with `mode_trace`, a second trace recorded with a band around
    the mode, fitted for the mode); `scene`: the scene to take everything but
    the device from (default: the default scene at the trace's rate)."""
    base = None if scene is None else _scene_text(scene)
    mode = None if mode_trace is None else _csv("mode_trace", mode_trace)
    if not isinstance(model, str):
        raise ValueError(f"model = {model!r} is not allowed: mass_damper_coulomb, mass_damper or two_mass")
    raw = _zwidth.identify_json(_csv("trace", trace), model, mode, base)
    return Identification(_zwidth.loads(raw))


def _csv(name: str, trace: Any) -> str:
    """A trace as the CSV the CLI reads (floats written to round-trip)."""
    if isinstance(trace, (str, os.PathLike)):
        path = os.fspath(trace)
        try:
            with open(path, encoding="utf-8") as f:
                return f.read()
        except (OSError, UnicodeDecodeError) as e:
            why = getattr(e, "strerror", None) or "not UTF-8 text"
            raise ValueError(f"{name} = {path} is not allowed: a readable CSV file ({why})") from None
    import numpy as np

    names = column_names(trace)
    if names is not None:
        missing = [c for c in COLUMNS if c not in names]
        if missing:
            raise ValueError(f"{name} = (columns {names}) is not allowed: "
                             f"needs the columns {', '.join(COLUMNS)}; missing {', '.join(missing)}")
        cols = [np.atleast_1d(np.asarray(trace[c], dtype=float)) for c in COLUMNS]
    else:
        a = np.asarray(trace, dtype=float)
        if a.ndim != 2 or a.shape[1] != 3:
            raise ValueError(f"{name} = (an array of shape {a.shape}) is not allowed: "
                             f"needs shape (n, 3), columns {', '.join(COLUMNS)}")
        cols = [a[:, i] for i in range(3)]
    if len({len(c) for c in cols}) != 1:
        raise ValueError(f"{name} = (columns of lengths {[len(c) for c in cols]}) is not allowed: "
                         "the three columns must have one length")
    lines = [",".join(COLUMNS)]
    lines += [f"{t!r},{f!r},{x!r}" for t, f, x in zip(*(c.tolist() for c in cols))]
    return "\n".join(lines) + "\n"
