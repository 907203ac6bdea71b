"""record and identify from Python against `zwidth record` and `zwidth
identify` on the same inputs: the same trace to the bit, the same
identification and written scene; a trace from a DataFrame-like dict, an
array or a file; bad traces a ValueError naming the line and column."""

import json
import subprocess

import numpy as np
import pytest

import zwidth
from test_engines import EX, cli

SCENE = EX / "seed_2018.json"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The CLI's trace of the seed device (its defaults: 20 s, lines to 20 Hz, 1 N)."""
    out = tmp_path_factory.mktemp("rec") / "trace.csv"
    subprocess.run([cli(), "record", "--scene", str(SCENE), "--out", str(out)],
                   check=True, capture_output=True)
    return out


def parse(path):
    rows = [tuple(map(float, line.split(","))) for line in path.read_text().splitlines()[1:] if line]
    return {c: np.array([r[i] for r in rows]) for i, c in enumerate(("t_s", "force_n", "position_m"))}


def test_record_equals_the_cli_s_trace_bit_for_bit(recorded):
    want = parse(recorded)
    got = zwidth.record(SCENE)
    for c in ("t_s", "force_n", "position_m"):
        assert got[c].tobytes() == want[c].tobytes(), c
    assert len(got["t_s"]) == 20_000  # 20 s at 1 kHz


def test_identify_equals_the_cli_s_fit_and_scene(recorded, tmp_path):
    out = tmp_path / "identified.json"
    r = subprocess.run([cli(), "identify", str(recorded), "--out", str(out), "--json"],
                       check=True, capture_output=True, text=True)
    want_id, want_scene = json.loads(r.stdout), json.loads(out.read_text())
    t = parse(recorded)
    for trace in (recorded, str(recorded), t, np.column_stack([t[c] for c in ("t_s", "force_n", "position_m")])):
        got = zwidth.identify(trace)
        assert got.identified == want_id
        assert got.scene == want_scene
    # The seed device is m = 0.52 kg, b = 13.2 N·s/m, f_c = 0.19 N
    # (examples/seed_2018.json); docs/identify.md: within 1–2 %.
    assert abs(got.mass / 0.52 - 1) < 0.02 and abs(got.damping / 13.2 - 1) < 0.02
    # The identified scene maps like any scene.
    m = zwidth.map(got.scene, accuracy="draft", b=[100])
    assert m.k_width > 0


def test_bad_traces_raise_value_error_naming_line_and_column(recorded):
    t = parse(recorded)
    bad = dict(t, force_n=t["force_n"].copy())
    bad["force_n"][10] = np.inf
    with pytest.raises(ValueError, match=r"^trace line 12, column 2 \(force_n\) = inf is not allowed"):
        zwidth.identify(bad)
    with pytest.raises(ValueError, match=r"needs the columns t_s, force_n, position_m; missing position_m"):
        zwidth.identify({"t_s": t["t_s"], "force_n": t["force_n"]})
    with pytest.raises(ValueError, match=r"needs shape \(n, 3\)"):
        zwidth.identify(np.zeros((10, 2)))
    with pytest.raises(ValueError, match=r"^model = rigid is not allowed"):
        zwidth.identify(recorded, "rigid")
    with pytest.raises(ValueError, match=r"^mode_trace is not allowed with model = mass_damper"):
        zwidth.identify(recorded, "mass_damper", mode_trace=recorded)
    with pytest.raises(ValueError, match=r"^period_s = "):
        zwidth.record(SCENE, period_s=0)
    with pytest.raises(ValueError, match=r"^peak_force = nan is not allowed: every number must be finite"):
        zwidth.record(SCENE, peak_force=float("nan"))


def test_a_structured_array_with_the_documented_columns_is_a_trace(recorded):
    """Issue 45: a structured array (np.genfromtxt(names=True)) gave numpy's
    TypeError; with the columns t_s, force_n, position_m it is the trace."""
    table = np.genfromtxt(recorded, delimiter=",", names=True)
    got = zwidth.identify(table)
    want = zwidth.identify(parse(recorded))
    assert got.to_dict() == want.to_dict()
    with pytest.raises(ValueError, match="missing position_m"):
        zwidth.identify(table[["t_s", "force_n"]])
