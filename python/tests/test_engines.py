"""The engines from Python against the CLI on the same inputs: every result
equal to `zwidth … --json` (the same computation, so to the bit, but the
elapsed time), every bad input a ValueError naming the field, and a long map
cancelled within a second by Ctrl-C or by an exception raised in its thread.

The CLI is the build `cargo test` (or `cargo build`) left in target/, or
$ZWIDTH_BIN; without one these tests fail, as CI's must."""

import ctypes
import json
import os
import pathlib
import signal
import subprocess
import threading
import time

import numpy as np
import pytest

import zwidth

ROOT = pathlib.Path(__file__).resolve().parents[2]
EX = ROOT / "examples"


def cli():
    """The zwidth binary: $ZWIDTH_BIN, else the newest in target/."""
    if os.environ.get("ZWIDTH_BIN"):
        return os.environ["ZWIDTH_BIN"]
    found = [p for p in (ROOT / "target/release/zwidth", ROOT / "target/debug/zwidth") if p.exists()]
    assert found, "no zwidth binary: run `cargo build` (or set ZWIDTH_BIN)"
    return str(max(found, key=lambda p: p.stat().st_mtime))


def cli_json(*args):
    out = subprocess.run([cli(), *args, "--json"], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


# Wall-clock measures in results: the only fields two runs may differ in.
CLOCK = {"elapsed_s", "search_s", "final_s", "mean_search_evaluation_s",
         "mean_final_evaluation_s", "saved_s"}


def without_elapsed(d):
    """A result without its wall-clock fields (the only ones that differ)."""
    if isinstance(d, dict):
        return {k: without_elapsed(v) for k, v in d.items() if k not in CLOCK}
    if isinstance(d, list):
        return [without_elapsed(v) for v in d]
    return d


@pytest.mark.parametrize(
    "scene, method, criterion, accuracy, bs",
    [
        ("seed_2018.json", "frequency", "impedance", "draft", [0, 400]),
        ("seed_2011.json", "time", "stability", "draft", [0, 300]),
        ("linear_1khz.json", "auto", "impedance", "standard", [0, 300]),
    ],
)
def test_a_map_equals_the_cli_s(scene, method, criterion, accuracy, bs):
    args = ["map", "--scene", str(EX / scene), "--method", method, "--criterion", criterion,
            "--accuracy", accuracy, "--b", ",".join(str(b) for b in bs)]
    want = cli_json(*args)
    got = zwidth.map(EX / scene, method=method, criterion=criterion, accuracy=accuracy, b=bs)
    assert without_elapsed(got.to_dict()) == without_elapsed(want)
    # The arrays are the JSON's numbers.
    assert got.k_width == want["k_width"]
    assert list(got.boundary["k_max"]) == [p["k_max"] for p in want["boundary"]]
    assert list(got.trials["k"]) == [p["k"] for p in want["points"]]
    assert got.trials["ok"].dtype == bool and len(got.trials["ok"]) == want["trials"]


def test_a_map_seeded_by_a_prior_equals_the_cli_s(tmp_path):
    # Issue 46: a map and its prediction, from Python as from the CLI.
    scene = EX / "seed_2011.json"
    args = ["map", "--scene", str(scene), "--method", "time", "--criterion", "stability",
            "--accuracy", "draft", "--b", "0,300"]
    first = zwidth.map(scene, method="time", criterion="stability", accuracy="draft", b=[0, 300])
    (tmp_path / "first.json").write_text(json.dumps(first.raw))
    want = cli_json(*args, "--prior-map", str(tmp_path / "first.json"))
    got = zwidth.map(scene, method="time", criterion="stability", accuracy="draft", b=[0, 300],
                     prior_map=first)
    assert without_elapsed(got.to_dict()) == without_elapsed(want)
    # The map's own device as the prediction: every column agrees, in
    # fewer trials than the first map's.
    assert got.raw["prior"]["disagreements"] == 0
    assert got.raw["trials"] < first.raw["trials"]
    # A scene to simulate first gives the same prediction, so the same trials.
    by_scene = zwidth.map(scene, method="time", criterion="stability", accuracy="draft",
                          b=[0, 300], prior_scene=scene)
    want = cli_json(*args, "--prior-scene", str(scene))
    assert without_elapsed(by_scene.to_dict()) == without_elapsed(want)
    assert by_scene.raw["points"] == got.raw["points"]


def test_a_scene_may_be_a_scene_a_dict_json_text_or_a_path():
    text = (EX / "seed_2011.json").read_text()
    sources = (zwidth.Scene(EX / "seed_2011.json"), json.loads(text), text,
               str(EX / "seed_2011.json"), EX / "seed_2011.json")
    runs = [zwidth.map(s, method="time", criterion="stability", accuracy="draft", b=[300])
            for s in sources]
    first = without_elapsed(runs[0].to_dict())
    assert all(without_elapsed(r.to_dict()) == first for r in runs[1:])


def test_a_noisy_map_carries_its_intervals_as_arrays():
    m = zwidth.map(EX / "seed_2018.json", accuracy="draft", b=[0, 400])
    lo, hi = m.k_width_interval
    assert lo <= m.k_width <= hi
    assert np.all(m.boundary["k_lo"] <= m.boundary["k_max"])
    assert np.all(m.boundary["k_max"] <= m.boundary["k_hi"])
    # Every BLA trial ran at least one realization, at most draft's 10.
    r = m.trials["realizations"]
    assert r.min() >= 1 and r.max() <= 10


def test_compare_equals_the_cli_s():
    want = cli_json("compare", "--accuracy", "draft")
    got = zwidth.compare(accuracy="draft")
    assert without_elapsed(got.to_dict()) == without_elapsed(want)
    assert list(got.maps) == [r["name"] for r in want["rows"]]
    for row in want["rows"]:
        assert got.maps[row["name"]].k_width == row["map"]["k_width"]


def test_a_trial_and_an_impedance_equal_the_cli_s():
    want = cli_json("trial", "--scene", str(EX / "seed_2011.json"), "--k", "20000", "--b", "30")
    assert zwidth.trial(EX / "seed_2011.json", 20000, 30) == want
    want = cli_json("impedance", "--scene", str(EX / "linear_1khz.json"), "--k", "20000", "--b", "30")
    got = zwidth.impedance(EX / "linear_1khz.json", 20000, 30)
    assert got.to_dict() == want
    assert list(got.magnitude) == want["magnitude"] and got.passive == want["passive"]


@pytest.mark.parametrize(
    "call, field, value",
    [
        (lambda: zwidth.map({"device": {"mass": -1}}), "scene.device.mass", "-1"),
        (lambda: zwidth.map(EX / "seed_2018.json", method="nope"), "method", "nope"),
        (lambda: zwidth.map(EX / "seed_2018.json", accuracy="drafty"), "accuracy", "drafty"),
        (lambda: zwidth.map(EX / "seed_2018.json", accuracy={"preset": "draft", "k_rel_tol": 0.9}),
         "accuracy.k_rel_tol", "0.9"),
        (lambda: zwidth.map(EX / "seed_2018.json", accuracy="drafty"), "accuracy", "draft, standard"),
        (lambda: zwidth.map(EX / "seed_2018.json", b_max=float("inf")), "b_max", "inf"),
        (lambda: zwidth.map(EX / "seed_2018.json", accuracy={"preset": "draft", "nope": 1}),
         "accuracy.nope", "unknown field `nope`"),
        (lambda: zwidth.map(EX / "seed_2018.json", accuracy={"preset": "draft", "realizations": 2.5}),
         "accuracy.realizations", "2.5"),
        (lambda: zwidth.compare(accuracy={"preset": "drafty"}), "accuracy.preset", "drafty"),
        (lambda: zwidth.map(EX / "seed_2018.json", b=[0, float("nan")]), "b[1]", "nan"),
        (lambda: zwidth.trial(EX / "seed_2011.json", "stiff", 1), "k", "stiff"),
        (lambda: zwidth.map(EX / "no_such.json"), "scene", "no_such.json"),
        (lambda: zwidth.compare(accuracy="draft", criterion="loud"), "criterion", "loud"),
        (lambda: zwidth.trial(EX / "seed_2011.json", float("nan"), 1), "k", "NaN"),
        (lambda: zwidth.trial(EX / "seed_2011.json", 1000, 1e9), "b", "1000000000"),
        (lambda: zwidth.impedance(EX / "linear_1khz.json", 1000, 1, method="time"), "method", "time"),
        (lambda: zwidth.impedance(EX / "linear_1khz.json", 1000, 1, method=None), "method", "None"),
        (lambda: zwidth.map(EX / "seed_2018.json", b="12"), "b", "'12'"),
        (lambda: zwidth.map(EX / "seed_2018.json", b=5), "b", "5"),
        (lambda: zwidth.map(EX / "seed_2011.json", prior_map=[]), "prior.boundary", "[]"),
        (lambda: zwidth.map(EX / "seed_2011.json", prior_map=[], prior_scene=EX / "seed_2011.json"),
         "prior_map", "(given)"),
        (lambda: zwidth.map(EX / "seed_2011.json", search="grid", prior_scene=EX / "seed_2011.json"),
         "prior", "grid"),
        (lambda: zwidth.trial(EX / "seed_2011.json", 10**400, 1), "k", "1000"),
        (lambda: zwidth.Scene("[1, 2]"), "scene", "JSON object"),
        # A NaN inside a dict, named by its path (the package's own JSON).
        (lambda: zwidth.Scene({"device": {"mass": float("nan")}}), "scene.device.mass", "nan"),
        (lambda: zwidth.map({"loop": {"sample_hz": float("inf")}}), "scene.loop.sample_hz", "inf"),
        (lambda: zwidth.Scene("/bin/ls"), "scene", "not UTF-8"),
        (lambda: zwidth.identify(EX / "seed_2018.json", None), "model", "None"),
        # 3.6e9 samples at 1 MHz: refused, not an allocation that ends the process.
        (lambda: zwidth.record({"loop": {"sample_hz": 1e6, "render_hz": 1000}}, duration_s=3600),
         "duration_s", "3600"),
    ],
)
def test_bad_input_raises_value_error_naming_the_field(call, field, value):
    with pytest.raises(ValueError) as e:
        call()
    msg = str(e.value)
    assert msg.startswith(f"{field} = "), msg
    assert value in msg and "allowed" in msg, msg
    assert "untagged" not in msg and "(as written)" not in msg, msg


LONG = dict(scene=EX / "mode_lag_2011.json", accuracy="reference")  # minutes


def test_an_exception_raised_in_the_map_s_thread_stops_it_within_a_second():
    raised = []

    def run():
        try:
            zwidth.map(**LONG)
        except KeyboardInterrupt:
            raised.append(time.monotonic())

    t = threading.Thread(target=run)
    t.start()
    time.sleep(0.5)
    sent = time.monotonic()
    n = ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(t.ident), ctypes.py_object(KeyboardInterrupt))
    assert n == 1
    t.join(timeout=5)
    assert not t.is_alive() and raised, "the map did not stop"
    assert raised[0] - sent < 1.0, raised[0] - sent


def test_ctrl_c_stops_a_map_within_a_second_and_the_gil_is_free_meanwhile():
    ticks = []
    stop = threading.Event()

    def tick():  # runs only while the map has released the GIL
        while not stop.is_set():
            ticks.append(time.monotonic())
            time.sleep(0.01)

    ticker = threading.Thread(target=tick)
    ticker.start()
    # Python's own Ctrl-C handler, as in a terminal: a process started in
    # the background by a non-interactive shell inherits SIGINT ignored.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    start = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            zwidth.map(**LONG)
        elapsed = time.monotonic() - start
    finally:
        stop.set()
        ticker.join()
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    assert elapsed < 1.5, elapsed  # 0.5 s before the signal, then < 1 s
    assert len([t for t in ticks if start < t < start + 0.5]) > 20, len(ticks)


def test_a_tune_equals_the_cli_s_and_reports_progress():
    # A small tune of the seed device's Butterworth cutoff: 6 evaluations at
    # draft on two B columns, one finalist re-mapped at standard.
    params = {"cutoff_hz": {"min": 50, "max": 499}}
    want = cli_json("tune", "--scene", str(EX / "seed_2018.json"), "--params", json.dumps(params),
                    "--objective", "k_width", "--max-evaluations", "6", "--finalists", "1",
                    "--replicates", "1", "--final-accuracy", "standard", "--b", "0,300")
    seen = []
    real = zwidth._zwidth.tune_json
    try:  # watch the fractions the progress bar is given
        zwidth._zwidth.tune_json = lambda spec, cb: real(spec, lambda f: (seen.append(f), cb and cb(f)))
        got = zwidth.tune(EX / "seed_2018.json", params, "k_width", max_evaluations=6, finalists=1,
                          replicates=1, final_accuracy="standard", b=[0, 300])
    finally:
        zwidth._zwidth.tune_json = real
    assert without_elapsed(got.to_dict()) == without_elapsed(want)
    ev = got.evaluations
    assert len(ev["cutoff_hz"]) == len(want["history"])
    assert np.all((50 <= ev["cutoff_hz"]) & (ev["cutoff_hz"] <= 499))
    assert ev["final"].sum() >= 1 and got.best["params"]["cutoff_hz"] in ev["cutoff_hz"]
    assert seen == sorted(seen) and all(0 <= f <= 1 for f in seen)


def test_a_bad_tune_names_the_field():
    with pytest.raises(ValueError, match=r"^params\.cutoff_hz"):
        zwidth.tune(EX / "seed_2018.json", {"cutoff_hz": {"min": 600, "max": 10}}, progress=False)
    with pytest.raises(ValueError, match=r"^max_evaluations = "):
        zwidth.tune(EX / "seed_2018.json", {"cutoff_hz": {"min": 50, "max": 400}},
                    max_evaluations=0, progress=False)


def test_the_accuracy_study_equals_the_cli_s():
    want = cli_json("accuracy", "--rates", "1000,10000", "--quantization", "1e-6")
    got = zwidth.accuracy([1000, 10000], quantization=1e-6)
    assert without_elapsed(got) == without_elapsed(want)
    with pytest.raises(ValueError, match=r"^rates\[1\] = inf is not allowed"):
        zwidth.accuracy([1000, float("inf")])
    with pytest.raises(ValueError, match=r"quantization"):
        zwidth.accuracy([1000], quantization=-1)


def test_a_scene_is_checked_and_completed_as_the_api_does():
    s = zwidth.Scene({"device": {"mass": 0.3}})
    # Every default filled in: the loop is SceneSpec's default
    # (crates/zwidth-core/src/zwidth/scene, the 2011 paper's 10 kHz).
    assert s.to_dict()["device"]["mass"] == 0.3
    assert s.to_dict()["loop"]["sample_hz"] == 10_000
    assert zwidth.Scene(s.to_dict()).to_dict() == s.to_dict()
    with pytest.raises(ValueError, match=r"^scene\.device\.mass = -1 is not allowed"):
        zwidth.Scene({"device": {"mass": -1}})
    with pytest.raises(ValueError, match=r"^scene\.device\.nope = \(as written\)"):
        zwidth.Scene({"device": {"nope": 1}})


def test_estimate_equals_the_cli_s():
    # `zwidth estimate` reads positions (one per line) on stdin and prints
    # velocities: the same numbers, printed to round-trip.
    x = np.round(1e-3 * np.sin(np.arange(500) * 0.02) / 1e-6) * 1e-6
    spec = {"kind": "butterworth", "cutoff_hz": 100}
    out = subprocess.run([cli(), "estimate", "--rate", "1000", "--estimator", json.dumps(spec)],
                         input="\n".join(repr(float(v)) for v in x), check=True, capture_output=True,
                         text=True).stdout.split()
    got = zwidth.estimate(x, spec, 1000.0)
    assert [float(v) for v in out] == list(got)
    with pytest.raises(ValueError, match=r"cutoff_hz"):
        zwidth.estimate(x, {"kind": "butterworth", "cutoff_hz": -1}, 1000.0)


def test_b_may_be_a_numpy_array():
    a = zwidth.map(EX / "seed_2011.json", method="time", criterion="stability", accuracy="draft",
                   b=np.array([0.0, 300.0]))
    want = zwidth.map(EX / "seed_2011.json", method="time", criterion="stability", accuracy="draft",
                      b=[0, 300])
    assert without_elapsed(a.to_dict()) == without_elapsed(want.to_dict())


def test_an_estimator_given_twice_keeps_both_rows():
    c = zwidth.compare(EX / "linear_1khz.json", accuracy="draft",
                       estimators=[{"kind": "fdm"}, {"kind": "fdm"}])
    assert len(c.to_dict()["rows"]) == 2
    first, second = list(c.maps)
    assert second == f"{first} (2)"
    assert without_elapsed(c.maps[first].to_dict()) == without_elapsed(c.maps[second].to_dict())


def _interrupted_after(seconds, call):
    """Run `call` with Python's own Ctrl-C handler, SIGINT sent after
    `seconds`; the time from the start until KeyboardInterrupt came out."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(seconds, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    start = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            call()
        return time.monotonic() - start
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)


def test_ctrl_c_stops_a_long_estimator_run_and_the_accuracy_study():
    # Issue 45: FOAW's best fit with outlier tolerance over a 4 096-sample
    # window costs milliseconds a sample, so run() on a million positions
    # held the interpreter deaf to Ctrl-C for over an hour; now it looks
    # every 100 ms. The accuracy study looks before each (estimator, rate).
    slow = zwidth.Estimator({"kind": "foaw", "fit": "best_r", "max_window": 4096,
                             "outlier_tolerance": True}, 1e4, 1e-6)
    positions = np.cumsum(np.full(10**6, 1e-6))
    elapsed = _interrupted_after(0.5, lambda: slow.run(positions))
    assert elapsed < 1.5, elapsed  # 0.5 s before the signal, then < 1 s
    # The estimator still answers (its history holds the samples it took).
    assert np.isfinite(slow.step(1.0))
    elapsed = _interrupted_after(0.5, lambda: zwidth.accuracy(list(range(1000, 41000, 1000)),
                                                               quantization=1e-6))
    assert elapsed < 3.0, elapsed


def test_compare_takes_the_api_s_number_of_estimators():
    """Issue 45: 0 or 21 estimators ran in Python where the API refuses them
    (422); the limit is one constant (zwidth-core's compare::MAX_ESTIMATORS)."""
    for n in (0, 21):
        with pytest.raises(ValueError, match=rf"^estimators = {n} is not allowed: give 1 to 20"):
            zwidth.compare(EX / "linear_1khz.json", accuracy="draft", estimators=[{"kind": "fdm"}] * n)
    # Refinement rounds: 0 to 3, as the CLI's --resolve-rounds and the API's
    # resolve_rounds (compare::MAX_RESOLVE_ROUNDS).
    for bad in (-1, 4, 10**30, 1.5, True, "2"):
        with pytest.raises(ValueError, match=r"^resolve_rounds = .* is not allowed: must be an integer 0 to 3"):
            zwidth.compare(EX / "linear_1khz.json", accuracy="draft", resolve_rounds=bad)
    with pytest.raises(ValueError, match=r"^estimators\[1\]\.cutoff_hz = "):
        zwidth.compare(EX / "linear_1khz.json", accuracy="draft",
                       estimators=[{"kind": "fdm"}, {"kind": "butterworth", "cutoff_hz": -1}])
