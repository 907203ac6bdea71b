"""The Python package's estimators against zwidth-dsp's golden vectors,
bit for bit (crates/zwidth-dsp/golden/vectors.txt, written by
`cargo run --release -p zwidth-core --example golden_vectors`), and every
bad input a ValueError naming the field."""

import pathlib
import struct
import threading

import numpy as np
import pytest

import zwidth

VECTORS = pathlib.Path(__file__).resolve().parents[2] / "crates/zwidth-dsp/golden/vectors.txt"


def bits(x):
    return struct.unpack("<Q", struct.pack("<d", x))[0]


def fnv(values):
    """FNV-1a 64 over each value's 8 little-endian bytes (the file's hash)."""
    h = 0xCBF29CE484222325
    for b in np.asarray(values, dtype="<f8").tobytes():
        h ^= b
        h = (h * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


def load():
    signals, cases = {}, []
    lines = VECTORS.read_text().splitlines()
    assert lines[0] == "zwidth-dsp golden vectors 1"
    cur = None
    for line in lines[1:]:
        w = line.split(" ")
        if w[0] == "#":
            continue
        if w[0] == "signal":
            cur = {"name": w[1], "rate": float(w[2]), "q": float(w[3]), "n": int(w[4]), "p": []}
            signals[cur["name"]] = cur
        elif w[0] == "p":
            cur["p"].append(struct.unpack("<d", struct.pack("<Q", int(w[1], 16)))[0])
        elif w[0] == "r":
            y = struct.unpack("<d", struct.pack("<Q", int(w[2], 16)))[0]
            cur["p"].extend([y] * int(w[1]))
        elif w[0] == "estimator":
            cases.append({"signal": cur["name"], "name": w[1], "stride": int(w[2]),
                          "hash": int(w[3], 16), "spec": " ".join(w[4:]), "v": []})
        elif w[0] == "v":
            cases[-1]["v"].append(int(w[1], 16))
    return signals, cases


SIGNALS, CASES = load()


def test_the_file_holds_every_case():
    assert len(SIGNALS) == 6 and len(CASES) == 90


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"{c['name']}-{c['signal']}")
def test_run_equals_the_golden_vectors_bit_for_bit(case):
    s = SIGNALS[case["signal"]]
    ys = np.array(s["p"], dtype=np.float64)
    assert len(ys) == s["n"]
    e = zwidth.Estimator(case["spec"], s["rate"], s["q"])
    v = e.run(ys)
    assert v.dtype == np.float64 and v.shape == ys.shape
    got = [bits(x) for x in v[:: case["stride"]]]
    first = next((i for i, (a, b) in enumerate(zip(got, case["v"])) if a != b), None)
    assert first is None, f"output {first * case['stride']}: {got[first]:016x} vs {case['v'][first]:016x}"
    assert fnv(v) == case["hash"]


def test_step_equals_run_and_reset_makes_it_new():
    s = SIGNALS["chirp"]
    ys = np.array(s["p"])
    for spec in [{"kind": "kalman", "q": 1e4}, {"kind": "foaw", "fit": "best_r", "max_window": 100}]:
        e = zwidth.Estimator(spec, s["rate"], s["q"])
        by_step = np.array([e.step(float(y)) for y in ys])
        e.reset()
        assert np.array_equal(e.run(ys), by_step)


def test_run_releases_the_gil_and_threads_agree():
    # Four threads each run their own estimator over a long trace: with the
    # GIL released in run() they overlap; every result equals the serial one.
    ys = np.cumsum(np.full(400_000, 1e-6))
    spec = {"kind": "butterworth", "cutoff_hz": 100, "order": 4}
    want = zwidth.Estimator(spec, 10_000, 1e-6).run(ys)
    got = [None] * 4

    def work(i):
        got[i] = zwidth.Estimator(spec, 10_000, 1e-6).run(ys)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(np.array_equal(g, want) for g in got)


def test_the_fingerprint_names_the_coefficients():
    a = zwidth.Estimator('{"kind":"butterworth","cutoff_hz":100}', 1000, 1e-6)
    b = zwidth.Estimator({"kind": "butterworth", "cutoff_hz": 100}, 1000, 1e-6)
    c = zwidth.Estimator({"kind": "butterworth", "cutoff_hz": 101}, 1000, 1e-6)
    assert a.fingerprint == b.fingerprint != c.fingerprint
    assert "butterworth(100 Hz, order 2)" in repr(a)
    assert zwidth.dsp_version and zwidth.__version__


@pytest.mark.parametrize(
    "args, field",
    [
        (({"kind": "nope"}, 1000, 1e-6), "unknown variant"),
        (({"kind": "butterworth", "cutoff_hz": 600}, 1000, 1e-6), "cutoff_hz = 600"),
        (({"kind": "kalman", "q": -1}, 1000, 1e-6), "q = -1"),
        (({"kind": "fdm"}, float("nan"), 1e-6), "rate = (not a number)"),
        (({"kind": "fdm"}, 1000, 0.0), "quantization = 0"),
        (({"kind": "foaw", "fit": "end", "max_window": 5000}, 1000, 1e-6), "max_window = 5000"),
        (("{not json", 1000, 1e-6), "not a valid estimator spec"),
        ((42, 1000, 1e-6), "spec = int"),
    ],
)
def test_bad_input_is_a_value_error_naming_the_field(args, field):
    with pytest.raises(ValueError) as e:
        zwidth.Estimator(*args)
    assert field in str(e.value)
    assert "NaN" not in str(e.value) and "inf" not in str(e.value)


def test_bad_positions_are_refused_and_change_nothing():
    e = zwidth.Estimator({"kind": "fdm"}, 1000, 1e-6)
    assert e.step(1e-3) == 0.0
    with pytest.raises(ValueError, match=r"positions\[1\]"):
        e.run(np.array([2e-3, np.nan]))
    with pytest.raises(ValueError, match=r"positions\[0\]"):
        e.step(float("inf"))
    # Unchanged: the next difference is from 1e-3.
    assert e.step(2e-3) == pytest.approx(1.0, rel=1e-12)
    with pytest.raises(ValueError, match=r"^positions = \(an array of shape \(2, 2\)\)"):
        e.run(np.zeros((2, 2)))


def test_positions_of_any_numeric_kind_are_converted_or_refused_naming_them():
    """Issue 45: float32, int, list and 2-D inputs raised numpy's TypeError
    ("cannot be cast"), a strided view "not contiguous" naming nothing."""
    ys = np.arange(12) * 1e-3  # m
    want = zwidth.Estimator({"kind": "fdm"}, 1000, 1e-6).run(ys)

    def run(x):
        return zwidth.Estimator({"kind": "fdm"}, 1000, 1e-6).run(x)

    for x in (ys.astype(np.float32), ys.tolist(), tuple(ys)):
        assert np.array_equal(run(x), run(np.asarray(x, dtype=float)))
    assert np.array_equal(run(np.arange(12)), run(np.arange(12.0)))
    # A strided view: every other sample of a longer array, copied.
    longer = np.repeat(ys, 2)
    assert np.array_equal(run(longer[::2]), want)
    # A table by its position_m column: what np.genfromtxt(names=True)
    # gives for the CSV header t_s,force_n,position_m.
    table = np.zeros(12, dtype=[("t_s", float), ("force_n", float), ("position_m", float)])
    table["position_m"] = ys
    assert np.array_equal(run(table), want)
    assert np.array_equal(run(table.view(np.recarray)), want)
    assert np.array_equal(run({"position_m": ys}), want)
    for bad, words in [
        (np.zeros((3, 2)), "shape (3, 2)"),
        ("0.001", "'0.001'"),
        (["a", "b"], "numbers (m)"),
        (np.zeros(3, dtype=[("x", float)]), "needs a position_m column"),
        (np.float64(1.0), "shape ()"),
    ]:
        with pytest.raises(ValueError) as e:
            run(bad)
        assert str(e.value).startswith("positions = ") and words in str(e.value), str(e.value)


def test_one_estimator_is_used_by_one_thread_at_a_time_as_documented():
    """The thread rule the docstring states: a second thread's call while a
    run holds the estimator is a RuntimeError and changes nothing; two
    estimators run in parallel."""
    assert "one thread at a time" in zwidth.Estimator.__doc__
    slow = {"kind": "foaw", "fit": "best_r", "max_window": 4096, "outlier_tolerance": True}
    e = zwidth.Estimator(slow, 1000, 1e-6)
    started, errors = threading.Event(), []

    def long_run():
        started.set()
        e.run(np.zeros(20_000))

    t = threading.Thread(target=long_run)
    t.start()
    started.wait()
    import time

    deadline = time.monotonic() + 30
    while t.is_alive() and not errors and time.monotonic() < deadline:
        try:
            e.step(0.0)
        except RuntimeError as x:
            errors.append(str(x))
        time.sleep(0.01)
    t.join()
    assert errors and "borrowed" in errors[0].lower(), errors


def test_a_dict_changed_while_it_is_read_is_a_value_error_not_a_panic():
    """Issue 45: a value whose conversion changes the dict made pyo3's
    iterator panic (a PanicException, which `except Exception` misses)."""
    spec = {"kind": "butterworth", "cutoff_hz": 100.0}

    class Sneaky:
        """An int by value (as numpy's are) that adds a key when read."""

        def __index__(self):
            spec["added_while_read"] = 1
            return 2

    spec["order"] = Sneaky()
    try:
        zwidth.Estimator(spec, 1000, 1e-6)
    except ValueError:
        pass  # refused naming a field: also fine
    except BaseException as x:  # noqa: BLE001 - a PanicException is a BaseException
        pytest.fail(f"{type(x).__name__}: {x}")


def test_a_position_whose_estimate_overflows_is_refused_and_resets():
    """Issue 45's probe: positions near 1e308 m made inf; as through the C
    ABI, the position is named and the estimator reset, so the next
    estimates are a fresh estimator's (FDM's (2e-3 - 1e-3) * 1e3 = 1)."""
    e = zwidth.Estimator({"kind": "fdm"}, 1000, 1e-6)
    e.step(1e308)
    with pytest.raises(ValueError, match=r"^positions\[0\] is not allowed: its estimate overflowed"):
        e.step(-1e308)
    e.step(1e-3)
    assert e.step(2e-3) == pytest.approx(1.0, rel=1e-12)
    # (1e308 - 0) * 1e3 overflows at the second position.
    with pytest.raises(ValueError, match=r"^positions\[1\] is not allowed: its estimate overflowed"):
        e.run(np.array([0.0, 1e308, -1e308, 0.0]))
    fresh = zwidth.Estimator({"kind": "fdm"}, 1000, 1e-6)
    assert np.array_equal(e.run(np.array([1e-3, 2e-3])), fresh.run(np.array([1e-3, 2e-3])))
    with pytest.raises(ValueError, match="overflowed"):
        zwidth.estimate([0.0, 1e308, -1e308], {"kind": "fdm"}, 1000)
