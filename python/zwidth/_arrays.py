"""Positions and traces from whatever array a user has: numpy arrays of any
dtype, lists, strided views, structured and record arrays (what
`np.genfromtxt(..., names=True)` reads from a CSV with a header), pandas
frames and dicts of columns. One place, used by `Estimator.run`,
`zwidth.estimate`, `zwidth.diff` and `zwidth.identify`: a bad input is a
ValueError naming the argument, never numpy's TypeError."""

from typing import Any, List, Optional

#: The column of positions (m) in a table: the CSV header the CLI writes
#: and reads (`t_s,force_n,position_m`).
POSITION = "position_m"


def column_names(x: Any) -> Optional[List[str]]:
    """The column names of a structured/record array, a DataFrame or a dict
    of columns; None for anything else."""
    names = getattr(getattr(x, "dtype", None), "names", None)
    if names:
        return list(names)
    if isinstance(x, dict):
        return [str(k) for k in x.keys()]
    if hasattr(x, "columns"):
        return [str(c) for c in x.columns]
    return None


def positions(name: str, x: Any):
    """`x` as a contiguous 1-D float64 array of positions (m): a table's
    `position_m` column, any numeric dtype converted, a strided view copied."""
    import numpy as np

    names = column_names(x)
    if names is not None:
        if POSITION not in names:
            raise ValueError(f"{name} = (a table with columns {names}) is not allowed: "
                             f"needs a {POSITION} column (m), as the CSV header "
                             "t_s,force_n,position_m names it")
        x = x[POSITION]
    if isinstance(x, (str, bytes)):
        raise ValueError(f"{name} = {x!r} is not allowed: positions (m) in a 1-D array, list or tuple")
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} = (a {type(x).__name__}) is not allowed: positions must be "
                         f"numbers (m) in a 1-D array, list or tuple ({e})") from None
    if a.ndim != 1:
        raise ValueError(f"{name} = (an array of shape {a.shape}) is not allowed: must be 1-D (m)")
    return np.ascontiguousarray(a)
