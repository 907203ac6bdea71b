"""The package's JSON (`_zwidth.loads`/`dumps`, serde_json in the native
module) against Python's own `json`, the independent implementation it
replaces: the same objects, the same key order, and refusals that name
where the bad value is. `import zwidth` and a map load neither `json` nor
`re` (docs/python.md, "Speed")."""

import json
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from zwidth import _zwidth

ROOT = pathlib.Path(__file__).resolve().parents[2]
EX = ROOT / "examples"


@pytest.mark.parametrize("path", sorted(EX.glob("*.json")), ids=lambda p: p.name)
def test_loads_is_json_loads_on_every_example_key_order_too(path):
    text = path.read_text(encoding="utf-8")
    ours, theirs = _zwidth.loads(text), json.loads(text)
    assert ours == theirs
    assert json.dumps(ours) == json.dumps(theirs)  # the same order of keys at every level


def test_loads_reads_every_json_type_as_json_loads_does():
    text = '{"b": [1, -2, 3.5, 1e-7, 18446744073709551615, true, false, null, "é\\n"], "a": {}, "c": []}'
    ours = _zwidth.loads(text)
    assert ours == json.loads(text)
    assert list(ours) == ["b", "a", "c"]
    assert [type(x) for x in ours["b"]] == [type(x) for x in json.loads(text)["b"]]


def test_loads_refuses_what_is_not_one_json_value():
    for text in ["", "{", "[1, 2", '{"a": 1} x', "NaN", "{'a': 1}"]:
        with pytest.raises(ValueError):
            _zwidth.loads(text)


def test_dumps_round_trips_through_json_loads():
    value = {
        "device": {"mass": 0.52, "tiny": 5e-324, "big": 1.7976931348623157e308, "n": -(2**63)},
        "list": [1, 2.5, "x", None, True, False, [], {}],
        "tuple": (1, 2),
        "u64": 2**64 - 1,
        "numpy": [np.float64(0.1), np.int64(7), np.float32(0.5)],
        "unicode": "N·s/m ±",
    }
    back = json.loads(_zwidth.dumps(value, "v"))
    expected = json.loads(json.dumps({**value, "tuple": [1, 2], "numpy": [0.1, 7, 0.5]}))
    assert back == expected
    assert list(back) == list(value)
    # Every float written so that it reads back to the same bits.
    assert [x.hex() for x in back["device"].values() if isinstance(x, float)] == [
        x.hex() for x in value["device"].values() if isinstance(x, float)
    ]


@pytest.mark.parametrize(
    "value, name, message",
    [
        ({"device": {"mass": math.nan}}, "scene", "^scene.device.mass = nan is not allowed: every number must be finite"),
        ({"f": [0.0, math.inf]}, "", r"^f\[1\] = inf is not allowed: every number must be finite"),
        ({"n": 2**64}, "spec", r"^spec.n = 18446744073709551616 is not allowed: an integer must fit in 64 bits"),
        ({1: 2}, "scene", "^scene key = 1 is not allowed: keys must be str"),
        ({"x": b"bytes"}, "scene", r"^scene.x = b'bytes' is not allowed: not a JSON value"),
        ({"x": {1, 2}}, "scene", r"^scene.x = \{1, 2\} is not allowed: not a JSON value"),
    ],
)
def test_dumps_refuses_what_json_cannot_hold_naming_where(value, name, message):
    with pytest.raises(ValueError, match=message):
        _zwidth.dumps(value, name)


def test_import_and_a_map_load_neither_json_nor_re():
    # What zwidth itself loads (a site hook may have loaded either before).
    code = (
        "import sys\n"
        "pre = set(sys.modules)\n"
        "import zwidth\n"
        "added = lambda: sorted(m for m in ('json', 're') if m in sys.modules and m not in pre)\n"
        "before = added()\n"
        f"m = zwidth.map({str(EX / 'linear_1khz.json')!r}, accuracy='draft', b=[0])\n"
        "print(before, added(), m.k_width > 0)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    assert out.stdout.split("\n")[0] == "[] [] True", out.stdout


def test_a_dict_that_contains_itself_is_a_value_error_not_a_crash():
    # Issue 45: the walk recursed without a limit, so a self-referential
    # argument (or a nesting 20 000 deep) overflowed the stack and killed
    # the interpreter. Now: a ValueError naming where, past MAX_DEPTH = 32.
    import zwidth

    d = {"kind": "fdm"}
    d["s"] = d
    with pytest.raises(ValueError, match=r"spec(\.s){32}.* nested more than 32"):
        zwidth.Estimator(d, 1e4, 1e-6)
    loop = []
    loop.append(loop)
    with pytest.raises(ValueError, match=r"nested more than 32"):
        _zwidth.dumps({"a": loop}, "scene")
    deep = {}
    for _ in range(20_000):
        deep = {"d": deep}
    with pytest.raises(ValueError, match=r"nested more than 32"):
        _zwidth.dumps(deep, "scene")
    # 32 levels are written (every spec is a few deep).
    ok = 0
    for _ in range(31):
        ok = [ok]
    assert json.loads(_zwidth.dumps({"a": ok}, "x"))["a"] is not None


def test_a_self_referential_dict_in_a_thread_with_a_small_stack():
    # The crash reproduced at 1 000 deep in a thread with a 512 KiB stack.
    import threading

    out = {}

    def run():
        d = {}
        d["d"] = d
        try:
            _zwidth.dumps(d, "scene")
        except ValueError as e:
            out["error"] = str(e)

    threading.stack_size(512 * 1024)
    try:
        t = threading.Thread(target=run)
        t.start()
        t.join()
    finally:
        threading.stack_size(0)
    assert "nested more than 32" in out["error"]
