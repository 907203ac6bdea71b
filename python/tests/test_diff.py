"""zwidth.diff: PyNumDiff's shape, `x_hat, dxdt_hat = method(x, dt, **params)`,
bit for bit the estimators' own output, and bad input a ValueError naming it."""

import numpy as np
import pytest

import zwidth

T = np.arange(2000) * 1e-3
X = np.round(1e-3 * np.sin(2 * np.pi * 2 * T) / 1e-6) * 1e-6  # a 1 µm encoder


@pytest.mark.parametrize("kind, params", [
    ("fdm", {}),
    ("butterworth", {"cutoff_hz": 50, "order": 2}),
    ("kalman", {"q": 1e4}),
    ("adaptive_kalman", {"q": 2.5e4}),
    ("foaw", {"fit": "best", "d": 1e-6, "max_window": 15}),
    ("levant", {"alpha": 7.25, "lambda": 2.567}),
])
def test_each_kind_is_its_estimator_bit_for_bit(kind, params):
    x_hat, v = getattr(zwidth.diff, kind)(X, 1e-3, quantization=1e-6, **params)
    want = zwidth.Estimator({"kind": kind, **params}, 1000.0, 1e-6).run(X)
    assert v.tobytes() == want.tobytes()
    assert x_hat.tobytes() == X.tobytes() and x_hat is not X


def test_fdm_is_the_backward_difference():
    # v_i = (x_i − x_{i−1})/dt (the 2011 paper's FDM), from the second
    # sample (the estimator multiplies by the rate: the last bit may differ).
    _, v = zwidth.diff.fdm(X, 1e-3)
    assert np.allclose(v[1:], (X[1:] - X[:-1]) / 1e-3, rtol=1e-12, atol=0)


def test_a_slow_sine_s_derivative_is_recovered():
    # d/dt of 1 mm·sin(2π·2t) is 4π mm/s·cos(2π·2t); a 50 Hz second-order
    # Butterworth lags it by about 2·ζ/ωc ≈ 4.5 ms and rounds the encoder's
    # 1 µm steps: within 6 % of the amplitude after its transient.
    _, v = zwidth.diff.butterworth(X, 1e-3, quantization=1e-6, cutoff_hz=50)
    true = 4e-3 * np.pi * np.cos(2 * np.pi * 2 * (T - 0.0045))
    assert np.max(np.abs(v[200:] - true[200:])) < 0.06 * 4e-3 * np.pi


@pytest.mark.parametrize("call, field", [
    (lambda: zwidth.diff.fdm(X, 0), "dt"),
    (lambda: zwidth.diff.fdm(X, float("nan")), "dt"),
    (lambda: zwidth.diff.fdm(np.zeros((3, 3)), 1e-3), "x"),
    (lambda: zwidth.diff.butterworth(X, 1e-3, cutoff_hz=-5), "cutoff_hz"),
    (lambda: zwidth.diff.kalman(X, 1e-3, q=1e4, nope=1), "nope"),
])
def test_bad_input_names_the_field(call, field):
    with pytest.raises(ValueError, match=field):
        call()


def test_a_table_read_with_its_header_is_differentiated_by_its_position_column():
    """Issue 45: np.genfromtxt(names=True), the usual way to read a CSV with
    a header, gave numpy's TypeError even with the documented column name."""
    import io

    csv = "t_s,force_n,position_m\n" + "".join(f"{i * 1e-3},0,{i * 1e-6}\n" for i in range(10))
    table = np.genfromtxt(io.StringIO(csv), delimiter=",", names=True)
    x_hat, v = zwidth.diff.fdm(table, 1e-3)
    want_x, want_v = zwidth.diff.fdm(table["position_m"], 1e-3)
    assert np.array_equal(x_hat, want_x) and np.array_equal(v, want_v)
    assert np.array_equal(zwidth.estimate(table, {"kind": "fdm"}, 1000), want_v)
    with pytest.raises(ValueError, match=r"^x = \(a table with columns \['t_s', 'force_n'\]\)"):
        zwidth.diff.fdm(table[["t_s", "force_n"]], 1e-3)
