"""The pictures the dashboard draws, with matplotlib (optional: `pip install
matplotlib`): a map in the style of the 2018 paper's Fig. 7 (each trial at
(B, K), the ones that render coloured by their fidelity error, the others
grey crosses, the boundary with its interval), several maps on one colour
scale, and a tune's landscape. Each returns the matplotlib Axes it drew on.
"""

from __future__ import annotations

from typing import Any, Optional, Sequence

__all__ = ["map", "compare", "tune"]


def _plt():
    try:
        import matplotlib.pyplot as plt
    except ImportError:
        raise ImportError("zwidth.plot needs matplotlib: pip install matplotlib") from None
    return plt


def _norm(results: Sequence[Any]):
    """One colour scale for the fidelity error (N·s/m) of every rendering
    trial of every result, so colours compare across maps."""
    import numpy as np
    from matplotlib.colors import Normalize

    values = [r.trials["fidelity"][r.trials["ok"]] for r in results]
    finite = np.concatenate([v[np.isfinite(v)] for v in values]) if values else np.array([])
    if finite.size == 0:
        return Normalize(0.0, 1.0)
    lo, hi = float(finite.min()), float(finite.max())
    return Normalize(lo, hi if hi > lo else lo + 1.0)


def map(result: Any, ax: Optional[Any] = None, *, title: Optional[str] = None,  # noqa: A001
        norm: Any = None, colorbar: bool = True) -> Any:
    """A MapResult in the style of the 2018 paper's Fig. 7: B (N·s/m)
    across, K (N/m) up; trials that render coloured by fidelity error,
    the others grey; the boundary K_max(B) with its interval shaded."""
    import numpy as np

    plt = _plt()
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4.5))
    t, bd = result.trials, result.boundary
    ok = t["ok"]
    norm = norm or _norm([result])
    ax.scatter(t["b"][~ok], t["k"][~ok], marker="x", s=12, color="0.7", label="does not render")
    sc = ax.scatter(t["b"][ok], t["k"][ok], c=t["fidelity"][ok], cmap="viridis", norm=norm, s=14,
                    label="renders")
    ax.plot(bd["b"], bd["k_max"], color="k", lw=1.5, label="boundary")
    if np.isfinite(bd["k_lo"]).any():
        ax.fill_between(bd["b"], bd["k_lo"], bd["k_hi"], color="k", alpha=0.15, lw=0,
                        label="interval")
    ax.set_xlabel("B (N·s/m)")
    ax.set_ylabel("K (N/m)")
    ax.set_title(title or f"K-width {result.k_width:.4g} N/m, B-width {result.b_width:.4g} N·s/m")
    if colorbar:
        ax.figure.colorbar(sc, ax=ax, label="fidelity error (N·s/m)")
    ax.legend(loc="upper right", fontsize="small")
    return ax


def compare(result: Any, *, ncols: int = 2) -> Any:
    """Every map of a CompareResult side by side on one colour scale; the
    array of Axes."""
    import numpy as np

    plt = _plt()
    names = list(result.maps)
    if not names:
        raise ValueError("result = (no maps) is not allowed: a comparison with at least one map")
    rows = -(-len(names) // ncols)
    fig, axes = plt.subplots(rows, ncols, figsize=(5 * ncols, 4 * rows), squeeze=False,
                             sharex=True, sharey=True)
    norm = _norm([result.maps[n] for n in names])
    for ax, n in zip(axes.flat, names):
        map(result.maps[n], ax, title=n, norm=norm, colorbar=False)
    for ax in list(axes.flat)[len(names):]:
        ax.set_visible(False)
    sm = plt.cm.ScalarMappable(norm=norm, cmap="viridis")
    fig.colorbar(sm, ax=list(np.ravel(axes)), label="fidelity error (N·s/m)")
    return axes


def tune(result: Any, ax: Optional[Any] = None, *, param: Optional[str] = None) -> Any:
    """A TuneResult's landscape: the score of every evaluation against one
    tuned parameter (the first by name unless `param`), the finalists'
    re-evaluations marked, the best circled."""
    plt = _plt()
    ev = result.evaluations
    names = [k for k in ev if k not in ("score", "feasible", "final", "trials")]
    p = param or names[0]
    if p not in names:
        raise ValueError(f"param = {p} is not allowed: one of {', '.join(names)}")
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4))
    search, final = ~ev["final"], ev["final"]
    ax.scatter(ev[p][search], ev["score"][search], s=16, label="search")
    ax.scatter(ev[p][final], ev["score"][final], s=30, marker="D", label="final")
    best = result.best["params"].get(p)
    if best is not None:
        ax.axvline(best, color="k", lw=1, ls="--", label=f"best {p} = {best:.4g}")
    ax.set_xlabel(p)
    ax.set_ylabel("score (the objective, larger is better)")
    ax.legend(fontsize="small")
    return ax
