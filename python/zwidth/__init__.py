"""zwidth from Python: the velocity estimators the simulator and a rig's
controller run, bit for bit (crates/zwidth-dsp through zwidth-core).

    >>> import numpy as np, zwidth
    >>> e = zwidth.Estimator({"kind": "butterworth", "cutoff_hz": 100}, 10_000, 1e-6)
    >>> v = e.run(np.linspace(0, 1e-3, 100))   # m in, m/s out

Units are SI. A bad spec, rate or position raises ValueError naming the
field, its value and what is allowed.
"""

from ._zwidth import Estimator, __version__, dsp_identity, dsp_version

__all__ = ["Estimator", "__version__", "dsp_identity", "dsp_version"]
