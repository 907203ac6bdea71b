"""zwidth from Python: the velocity estimators the simulator and a rig's
controller run, bit for bit (crates/zwidth-dsp through zwidth-core), and the
Z-width engines in process.

    >>> import numpy as np, zwidth
    >>> e = zwidth.Estimator({"kind": "butterworth", "cutoff_hz": 100}, 10_000, 1e-6)
    >>> v = e.run(np.linspace(0, 1e-3, 100))   # m in, m/s out
    >>> m = zwidth.map("examples/seed_2018.json", accuracy="draft", b=[0, 400])
    >>> m.k_width, m.boundary["k_max"]           # N/m

Units are SI. A bad spec, scene, rate or position raises ValueError naming
the field, its value and what is allowed. The engines release the GIL while
they run, and Ctrl-C cancels them. `zwidth.Client` drives a running service.
"""

from ._zwidth import Estimator, __version__, dsp_identity, dsp_version
from .engines import (
    CompareResult,
    ImpedanceResult,
    MapResult,
    Scene,
    TuneResult,
    accuracy,
    compare,
    estimate,
    impedance,
    map,
    trial,
    tune,
)
from .identify import Identification, identify, record

# The client and the PyNumDiff-shaped functions load on first use
# (`zwidth.Client`, `zwidth.diff`; `zwidth.plot` needs matplotlib): `import
# zwidth` stays a few milliseconds (docs/python.md, "Speed").
_LAZY = {"ApiError": "client", "Client": "client", "diff": None, "plot": None}


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module 'zwidth' has no attribute {name!r}")
    import importlib

    module = importlib.import_module(f".{_LAZY[name] or name}", __name__)
    value = module if _LAZY[name] is None else getattr(module, name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "ApiError",
    "Client",
    "CompareResult",
    "Estimator",
    "Identification",
    "ImpedanceResult",
    "MapResult",
    "Scene",
    "__version__",
    "accuracy",
    "compare",
    "diff",
    "estimate",
    "dsp_identity",
    "dsp_version",
    "identify",
    "impedance",
    "map",
    "record",
    "trial",
    "tune",
    "TuneResult",
]
