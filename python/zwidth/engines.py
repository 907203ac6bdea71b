"""The Z-width engines in process: a map, a comparison of estimators, one
wall hit, the impedance at one (K, B).

Scenes and specs are the API's (docs/service.md): a dict, JSON text or the
path of a JSON file. Results carry numpy arrays and `.to_dict()`, which is
exactly what `zwidth map --json` (`compare`, `trial`, `impedance`) prints for
the same inputs (but the elapsed time). Units are SI: K in N/m, B in N·s/m.

The GIL is released while an engine runs, and Ctrl-C (or an exception raised
in the calling thread) cancels it within a tenth of a second. A bad input
raises ValueError naming the field, its value and what is allowed.
"""

from __future__ import annotations

import math
import os

from . import _zwidth

# The annotations are for type checkers only (`from __future__ import
# annotations` keeps them unevaluated): `typing` and `dataclasses` cost half
# of `import zwidth` (docs/python.md, "Speed").
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, Dict, Optional, Sequence, Union

    import numpy as np

    SceneLike = Union["Scene", Dict[str, Any], str, "os.PathLike[str]"]
    AccuracyLike = Union[str, Dict[str, Any]]

__all__ = [
    "Scene",
    "MapResult",
    "CompareResult",
    "ImpedanceResult",
    "map",
    "compare",
    "tune",
    "TuneResult",
    "trial",
    "impedance",
    "accuracy",
    "estimate",
]


class Scene:
    """A scene, checked as the API checks it (`docs/service.md`), every
    default filled in: `Scene(dict | JSON text | path)`. A bad field
    raises ValueError naming it (`scene.device.mass = -1 is not allowed:
    …`). Every engine takes a Scene where it takes a scene."""

    def __init__(self, source: "SceneLike"):
        self.spec: Dict[str, Any] = _zwidth.loads(_zwidth.scene_json(_scene_text(source)))

    def to_dict(self) -> Dict[str, Any]:
        """The scene as the API stores it (defaults filled in)."""
        return self.spec

    def __repr__(self) -> str:
        d, loop, est = self.spec["device"], self.spec["loop"], self.spec["estimator"]
        return (f"Scene(mass={d['mass']} kg, sample_hz={loop['sample_hz']}, "
                f"estimator={est.get('kind')!r})")


def _scene_dict(scene: "SceneLike") -> Dict[str, Any]:
    """A scene as a dict: a Scene's spec, a dict as it is, JSON text
    parsed, a path read."""
    if isinstance(scene, Scene):
        return scene.spec
    if isinstance(scene, dict):
        return scene
    # A str is JSON text unless it names a file (or cannot be JSON).
    is_text = isinstance(scene, str) and (
        scene.lstrip().startswith("{") or (not os.path.exists(scene) and _is_json(scene)))
    if isinstance(scene, os.PathLike) or (isinstance(scene, str) and not is_text):
        path = os.fspath(scene)
        try:
            with open(path, encoding="utf-8") as f:
                text = f.read()
        except (OSError, UnicodeDecodeError) as e:
            why = getattr(e, "strerror", None) or "not UTF-8 text"
            raise ValueError(
                f"scene = {path} is not allowed: a scene dict, JSON text or a readable JSON file ({why})"
            ) from None
    elif isinstance(scene, str):
        text = scene
    else:
        raise ValueError(
            f"scene = {type(scene).__name__} is not allowed: a scene dict, JSON text or the path of a JSON file"
        )
    try:
        parsed = _zwidth.loads(text)
    except ValueError as e:
        raise ValueError(f"scene = (as written) is not allowed: not JSON ({e})") from None
    if not isinstance(parsed, dict):
        raise ValueError(f"scene = {text.strip()[:60]} is not allowed: must be a JSON object (a scene)")
    return parsed


def _scene_text(scene: "SceneLike") -> str:
    """A scene as the JSON text the engines take (`_scene_dict`, written)."""
    return _zwidth.dumps(_scene_dict(scene), "scene")


def _is_json(text: str) -> bool:
    try:
        _zwidth.loads(text)
    except ValueError:
        return False
    return True


def _word(name: str, value: Any) -> str:
    """A choice argument (`method`, `criterion`, …) as a str, or ValueError."""
    if not isinstance(value, str):
        raise ValueError(f"{name} = {value!r} is not allowed: must be a word such as 'auto' (a str)")
    return value


def _numbers(name: str, values: Any, unit: str) -> list:
    """A list of finite numbers (a list, tuple or 1-D array), or ValueError."""
    if isinstance(values, (str, bytes, dict)) or not hasattr(values, "__iter__"):
        raise ValueError(f"{name} = {values!r} is not allowed: must be a list of numbers ({unit})")
    out = list(values)
    for i, x in enumerate(out):
        _finite(f"{name}[{i}]", x, unit)
    return [float(x) for x in out]


def _column(rows: Sequence[Dict[str, Any]], key: str) -> "np.ndarray":
    """One field of every row as a float array; NaN where a row has none.
    (numpy is imported on first use: `import zwidth` and a map's JSON need
    it not.)"""
    import numpy as np

    return np.array([r.get(key, np.nan) for r in rows], dtype=float)


class _once:
    """A property computed on first read and kept in the instance (what
    `functools.cached_property` does, without importing functools: `import
    zwidth` stays about a millisecond)."""

    def __init__(self, f: Any):
        self.f, self.name, self.__doc__ = f, f.__name__, f.__doc__

    def __get__(self, obj: Any, cls: Any = None) -> Any:
        if obj is None:
            return self
        value = obj.__dict__[self.name] = self.f(obj)
        return value


class MapResult:
    """A Z-width map: its boundary (with intervals on a noisy scene) and
    every trial that found it.

    `boundary` holds arrays `b`, `k_max`, `k_lo`, `k_hi` (NaN where a point
    has no interval); `trials` arrays `k`, `b`, `ok` (renders: passive or
    stable), `decided`, `margin`, `margin_se`, `realizations`, `fidelity`
    (NaN where a trial has none).
    """

    def __init__(self, raw: Dict[str, Any]):
        self.raw = raw
        self.k_width: float = raw["k_width"]
        self.b_width: float = raw["b_width"]
        kwi, bwi = raw.get("k_width_interval"), raw.get("b_width_interval")
        self.k_width_interval: Optional[tuple] = tuple(kwi) if kwi else None
        self.b_width_interval: Optional[tuple] = tuple(bwi) if bwi else None

    @classmethod
    def _from(cls, raw: Dict[str, Any]) -> "MapResult":
        return cls(raw)

    @_once
    def boundary(self) -> Dict[str, "np.ndarray"]:
        bd = self.raw["boundary"]
        return {k: _column(bd, k) for k in ("b", "k_max", "k_lo", "k_hi")}

    @_once
    def trials(self) -> Dict[str, "np.ndarray"]:
        import numpy as np

        pts = self.raw["points"]
        return {
            "k": _column(pts, "k"),
            "b": _column(pts, "b"),
            "ok": np.array([p.get("passive", p.get("stable", False)) for p in pts], dtype=bool),
            "decided": np.array([p.get("decided", True) for p in pts], dtype=bool),
            "margin": _column(pts, "margin"),
            "margin_se": _column(pts, "margin_se"),
            "realizations": np.array([p.get("realizations", 1) for p in pts], dtype=np.int64),
            "fidelity": _column(pts, "fidelity"),
        }

    def to_dict(self) -> Dict[str, Any]:
        """The result as `zwidth map --json` prints it."""
        return self.raw

    def __repr__(self) -> str:
        return (f"MapResult(k_width={self.k_width}, b_width={self.b_width}, "
                f"k_width_interval={self.k_width_interval}, trials={self.raw['trials']})")


class _Record:
    """A read-only record of the fields a subclass annotates (what a frozen
    dataclass gives, without importing dataclasses): equal when every field
    is; `raw` left out of the repr."""

    _fields = ()

    def __init_subclass__(cls) -> None:
        # The subclass's own annotations, in order (unevaluated strings; on
        # Python 3.14 they may live behind the class's __annotations__ only).
        own = cls.__dict__.get("__annotations__")
        cls._fields = tuple(own if own is not None else cls.__annotations__)

    def __init__(self, **values: Any):
        if set(values) != set(self._fields):
            raise TypeError(f"{type(self).__name__} takes {', '.join(self._fields)}")
        for k in self._fields:
            object.__setattr__(self, k, values[k])

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"{type(self).__name__} is read-only: cannot set {name}")

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return all(_same(getattr(self, k), getattr(other, k)) for k in self._fields)

    __hash__ = None  # type: ignore[assignment]  # equal by value, mutable fields

    def __repr__(self) -> str:
        shown = ", ".join(f"{k}={getattr(self, k)!r}" for k in self._fields if k != "raw")
        return f"{type(self).__name__}({shown})"


def _same(a: Any, b: Any) -> bool:
    """Field equality, numpy arrays compared whole."""
    if hasattr(a, "shape") and hasattr(b, "shape"):
        return a.shape == b.shape and bool((a == b).all())
    return bool(a == b)


class CompareResult(_Record):
    """Every estimator's map on one scene (the 2018 paper's Table I):
    `maps` by estimator name in the rows' order (a name given twice: its
    second row as "name (2)"), and the raw result."""

    maps: Dict[str, MapResult]
    raw: Dict[str, Any]

    def to_dict(self) -> Dict[str, Any]:
        """The result as `zwidth compare --json` prints it."""
        return self.raw


class ImpedanceResult(_Record):
    """The rendered wall's impedance on the probe's lines: `freq_hz`,
    `magnitude` (N·s/m), `phase_deg` (numpy arrays); `passive` and
    `fidelity` (N·s/m)."""

    freq_hz: np.ndarray
    magnitude: np.ndarray
    phase_deg: np.ndarray
    passive: bool
    fidelity: float
    raw: Dict[str, Any]

    def to_dict(self) -> Dict[str, Any]:
        """The result as `zwidth impedance --json` prints it."""
        return self.raw


def _number(name: str, x: Any) -> float:
    """A wall parameter as a float, or ValueError naming it (the engine
    checks its range)."""
    try:
        return float(x)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} = {x!r} is not allowed: must be a number") from None


def _finite(name: str, x: Any, unit: str) -> None:
    """JSON has no inf or NaN: say so by the argument's name."""
    try:
        ok = math.isfinite(float(x))
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ValueError(f"{name} = {x} is not allowed: must be a finite number ({unit})")


def _accuracy(accuracy: AccuracyLike) -> str:
    return _zwidth.dumps(accuracy, "accuracy")


def map(  # noqa: A001 - the product's word for it
    scene: SceneLike,
    *,
    method: str = "auto",
    criterion: str = "impedance",
    search: str = "bisect",
    accuracy: AccuracyLike = "standard",
    b: Optional[Sequence[float]] = None,
    b_max: float = 1000.0,
    k_max: float = 1e7,
    prior_scene: Optional[SceneLike] = None,
    prior_map: Optional[Any] = None,
) -> MapResult:
    """The Z-width map of `scene`: the (K, B) region it renders.

    `method`: auto | analytic | time | frequency; `criterion`: impedance |
    stability | strict_passivity; `search`: bisect | robust_bisect | trace |
    grid | psi; `accuracy`: draft | standard | reference, or a dict of knobs
    (`{"preset": "draft", "k_rel_tol": 0.02}`); `b`: only these dampings
    (N·s/m); `b_max` (N·s/m) and `k_max` (N/m) bound the search.

    A prediction seeds each column's bisection (`zwidth map --prior-scene`,
    `--prior-map`): `prior_scene`, a scene simulated first, or `prior_map`,
    a `MapResult`, the dict of `zwidth map --json`, or a list of boundary
    points `{"b", "k_max", "k_lo", "k_hi"}`. The result is the
    map's own; `raw["prior"]` sets the prediction beside each column.
    """
    _finite("b_max", b_max, "N·s/m")
    _finite("k_max", k_max, "N/m")
    if prior_scene is not None and prior_map is not None:
        raise ValueError("prior_map = (given) is not allowed with prior_scene: give one prediction")
    spec: Dict[str, Any] = {
        "scene": _scene_dict(scene),
        "method": _word("method", method),
        "criterion": _word("criterion", criterion),
        "search": _word("search", search),
        "accuracy": accuracy,
        "b_max": b_max,
        "k_max": k_max,
    }
    if b is not None:
        spec["b"] = _numbers("b", b, "N·s/m")
    if prior_scene is not None:
        spec["prior"] = {"scene": _scene_dict(prior_scene)}
    elif prior_map is not None:
        if isinstance(prior_map, MapResult):
            boundary = prior_map.raw["boundary"]
        elif isinstance(prior_map, dict) and "boundary" in prior_map:  # `zwidth map --json`
            boundary = prior_map["boundary"]
        else:
            boundary = prior_map
        spec["prior"] = {"boundary": boundary}
    return MapResult._from(_zwidth.loads(_zwidth.map_json(_zwidth.dumps(spec, ""))))


def compare(
    scene: Optional[SceneLike] = None,
    *,
    accuracy: AccuracyLike = "standard",
    criterion: str = "impedance",
    estimators: Optional[Sequence[Dict[str, Any]]] = None,
    resolve_rounds: int = 0,
) -> CompareResult:
    """Every estimator of the 2018 paper on `scene` (None: the paper's
    simulated device), each mapped with the paper's parameters; or the
    `estimators` given (API estimator specs, `[{"kind": "fdm"}, …]`).
    `resolve_rounds` (0–3) maps the rows of unresolved K-width orders again,
    each round at half the K resolution before, as `zwidth compare
    --resolve-rounds`."""
    text = None if scene is None else _scene_text(scene)
    est = None if estimators is None else _zwidth.dumps(list(estimators), "estimators")
    if isinstance(resolve_rounds, bool) or not isinstance(resolve_rounds, int) or not 0 <= resolve_rounds <= 3:
        raise ValueError(f"resolve_rounds = {resolve_rounds!r} is not allowed: must be an integer 0 to 3")
    raw = _zwidth.loads(
        _zwidth.compare_json(text, _accuracy(accuracy), _word("criterion", criterion), est, resolve_rounds)
    )
    maps: Dict[str, MapResult] = {}
    for row in raw["rows"]:
        # An estimator given twice keeps both rows: "name (2)" for the second.
        key, n = row["name"], 1
        while key in maps:
            n += 1
            key = f"{row['name']} ({n})"
        maps[key] = MapResult._from(row["map"])
    return CompareResult(maps=maps, raw=raw)


class TuneResult:
    """A tune's outcome (`zwidth tune --json`): `best` (its parameters,
    objective and map), and `evaluations`, every evaluation as arrays: one
    per tuned parameter by name, plus `score` (the objective as one number
    to maximize), `feasible`, `final` (re-evaluated at the final accuracy)
    and `trials`."""

    def __init__(self, raw: Dict[str, Any]):
        self.raw = raw
        self.best: Dict[str, Any] = raw["best"]

    @_once
    def evaluations(self) -> Dict[str, "np.ndarray"]:
        import numpy as np

        h = self.raw["history"]
        names = sorted({k for e in h for k in e["params"]})
        out = {n: np.array([e["params"].get(n, np.nan) for e in h], dtype=float) for n in names}
        out["score"] = np.array([e["score"] for e in h], dtype=float)
        out["feasible"] = np.array([e["feasible"] for e in h], dtype=bool)
        out["final"] = np.array([e["phase"] == "final" for e in h], dtype=bool)
        out["trials"] = np.array([e["trials"] for e in h], dtype=np.int64)
        return out

    def to_dict(self) -> Dict[str, Any]:
        """The result as `zwidth tune --json` prints it."""
        return self.raw

    def __repr__(self) -> str:
        return f"TuneResult(best={self.best.get('params')}, evaluations={self.raw['evaluations']})"


def tune(
    scene: SceneLike,
    params: Dict[str, Dict[str, Any]],
    objective: Union[str, Dict[str, float]] = "k_width",
    *,
    method: str = "auto",
    criterion: str = "impedance",
    search: str = "robust_bisect",
    accuracy: AccuracyLike = "draft",
    final_accuracy: AccuracyLike = "reference",
    finalists: int = 3,
    replicates: int = 3,
    solver: str = "auto",
    seed: int = 0,
    max_evaluations: int = 40,
    constraint: Optional[str] = None,
    b: Optional[Sequence[float]] = None,
    progress: bool = True,
) -> TuneResult:
    """Tune the scene's estimator parameters (docs/tuning.md): `params`
    maps each to its bounds (`{"cutoff_hz": {"min": 10, "max": 499}}`),
    `objective` is k_width | b_width | max_fidelity_error | area or a
    weighted dict. With `progress`, a bar on stderr (tqdm's when installed)."""
    spec: Dict[str, Any] = {
        "scene": _scene_dict(scene), "params": params, "objective": objective,
        "method": method, "criterion": criterion, "search": search,
        "accuracy": accuracy, "final_accuracy": final_accuracy, "finalists": finalists,
        "replicates": replicates, "solver": solver, "seed": seed,
        "max_evaluations": max_evaluations, "b_max": 1000.0, "k_max": 1e7,
    }
    if constraint is not None:
        spec["constraint"] = constraint
    if b is not None:
        spec["b"] = _numbers("b", b, "N·s/m")
    from ._progress import Bar

    bar = Bar("tune") if progress else None
    try:
        raw = _zwidth.tune_json(_zwidth.dumps(spec, ""), bar.update if bar else None)
    finally:
        if bar:
            bar.close()
    return TuneResult(_zwidth.loads(raw))


def trial(scene: SceneLike, k: float, b: float) -> Dict[str, Any]:
    """One wall hit (the 2011 paper's §2.4, time engine) at K (N/m) and
    B (N·s/m): whether it is stable, and its measures."""
    return _zwidth.loads(_zwidth.trial_json(_scene_text(scene), _number("k", k), _number("b", b)))


def impedance(
    scene: SceneLike,
    k: float,
    b: float,
    *,
    method: str = "auto",
    accuracy: AccuracyLike = "standard",
) -> ImpedanceResult:
    """The impedance of the wall (K N/m, B N·s/m) rendered on `scene` over
    the probe band: the closed form on a linear scene, else the simulated
    probe (`method`: auto | analytic | frequency)."""
    raw = _zwidth.loads(
        _zwidth.impedance_json(
            _scene_text(scene), _number("k", k), _number("b", b), _word("method", method),
            _accuracy(accuracy)
        )
    )
    import numpy as np

    return ImpedanceResult(
        freq_hz=np.array(raw["freq_hz"]),
        magnitude=np.array(raw["magnitude"]),
        phase_deg=np.array(raw["phase_deg"]),
        passive=raw["passive"],
        fidelity=raw["fidelity"],
        raw=raw,
    )


def accuracy(
    rates: Sequence[float] = (1e3, 2e3, 5e3, 1e4, 2e4, 5e4, 1e5),
    *,
    quantization: float = 1e-6,
) -> Dict[str, Any]:
    """The 2011 paper's Fig. 2 study: every estimator's RMS velocity error
    (m/s) on its test signal at each sample rate (Hz) through an encoder of
    step `quantization` (m); `zwidth accuracy --json`'s report (`rates`,
    and per estimator `name` and `rms_error`, one per rate)."""
    rates = _numbers("rates", rates, "Hz")
    _finite("quantization", quantization, "m")
    return _zwidth.loads(_zwidth.accuracy_json(rates, float(quantization)))


def estimate(positions: Any, estimator: Union[str, Dict[str, Any]], rate_hz: float,
             quantization: float = 1e-6) -> "np.ndarray":
    """Velocities (m/s) for positions (m) sampled at `rate_hz` through an
    encoder of step `quantization` (m), by `estimator` (an API estimator
    spec): `zwidth estimate` in process, the same bits (zwidth-dsp)."""
    from ._arrays import positions as as_positions
    from ._zwidth import Estimator

    return Estimator(estimator, float(rate_hz), float(quantization)).run(
        as_positions("positions", positions))
