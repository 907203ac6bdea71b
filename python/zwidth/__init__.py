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

from . import diff
from ._zwidth import Estimator, __version__, dsp_identity, dsp_version
from .client import ApiError, Client
from .identify import Identification, identify, record
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
