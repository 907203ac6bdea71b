"""zwidth.plot draws what the results hold: one marker per trial (those
that render coloured by fidelity on one scale across maps), the boundary,
its interval, a tune's evaluations; matplotlib's Agg backend, no display."""

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import zwidth  # noqa: E402
import zwidth.plot  # noqa: E402
from test_engines import EX  # noqa: E402


def test_a_map_plot_has_every_trial_and_the_boundary(tmp_path):
    m = zwidth.map(EX / "seed_2018.json", accuracy="draft", b=[0, 200, 400])
    ax = zwidth.plot.map(m)
    fails, renders = ax.collections[0], ax.collections[1]
    ok = m.trials["ok"]
    assert len(fails.get_offsets()) == (~ok).sum() and len(renders.get_offsets()) == ok.sum()
    assert np.array_equal(renders.get_array(), m.trials["fidelity"][ok])
    line = ax.lines[0]
    assert list(line.get_ydata()) == list(m.boundary["k_max"])
    assert len(ax.collections) == 3  # + the interval (a noisy scene)
    ax.figure.savefig(tmp_path / "map.png")
    assert (tmp_path / "map.png").stat().st_size > 10_000


def test_a_compare_plot_shares_one_colour_scale():
    c = zwidth.compare(EX / "linear_1khz.json", accuracy="draft")
    axes = zwidth.plot.compare(c)
    norms = {(a.collections[1].norm.vmin, a.collections[1].norm.vmax)
             for a in axes.flat if a.get_visible()}
    assert len(norms) == 1
    every = np.concatenate([r.trials["fidelity"][r.trials["ok"]] for r in c.maps.values()])
    assert norms == {(every.min(), every.max())}


def test_a_tune_plot_has_every_evaluation():
    t = zwidth.tune(EX / "seed_2018.json", {"cutoff_hz": {"min": 50, "max": 499}}, max_evaluations=5,
                    finalists=1, replicates=1, final_accuracy="draft", b=[0], progress=False)
    ax = zwidth.plot.tune(t)
    n = sum(len(c.get_offsets()) for c in ax.collections)
    assert n == len(t.evaluations["score"])
    with pytest.raises(ValueError, match="^param = q is not allowed"):
        zwidth.plot.tune(t, param="q")
