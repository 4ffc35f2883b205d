"""analysis.bootstrap against rliable itself: the same random state gives the same intervals, bit for bit.

rliable is the reference: each case runs ``rliable.library.get_interval_estimates`` (or
``create_performance_profile``) on the same inputs with its global generator seeded as analysis.stats.seeded
seeds it, and compares points and intervals with ``==``. The cases cover both index streams of
analysis.bootstrap.IndexStream: matrices of one number of runs (one ``randint`` draw) and of several (the
masked-and-rejected words), a one-run matrix (draws nothing), and chunks (the stream continues across them).
"""

from __future__ import annotations

import numpy as np
import pytest
from rliable import library as rly
from rliable import metrics

from analysis import bootstrap as bs
from analysis import stats
from analysis.stats import seeded

REPS = 300


def _rliable(scores, func, reps=REPS, seed=3):
    with seeded(seed) as rs:
        points, cis = rly.get_interval_estimates({"k": scores}, func, reps=reps, random_state=rs)
    return np.asarray(points["k"], dtype=float), np.asarray(cis["k"])


def _ours(stat, arrays, reps=REPS, seed=3):
    return bs.interval_estimates(stat, arrays, reps, seed)


def _equal(ours, ref):
    np.testing.assert_array_equal(ours[0], ref[0])
    np.testing.assert_array_equal(ours[1], ref[1])


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(7)
    return {"m6": rng.uniform(0, 1.2, (6, 9)), "m10": rng.uniform(0, 1, (10, 4)), "y6": rng.uniform(0, 1, (6, 9)),
            "x5": rng.uniform(0, 1, (5, 3)), "y7": rng.uniform(0, 1, (7, 3)), "one": rng.uniform(0, 1, (1, 3)),
            "ties": np.round(rng.uniform(0, 1, (4, 3)), 1)}


def test_aggregates_equal_rliable(data):
    def ref(x):
        return np.array([metrics.aggregate_iqm(x), metrics.aggregate_mean(x), metrics.aggregate_optimality_gap(x)])

    _equal(_ours(bs.AGGREGATES, [data["m6"]]), _rliable(data["m6"], ref))
    _equal(_ours(bs.MEDIAN, [data["m10"]]), _rliable(data["m10"], lambda x: np.array([metrics.aggregate_median(x)])))


def test_column_means_equal_rliable(data):
    # ten runs: the per-column sums are longer than NumPy's unrolled blocks
    _equal(_ours(bs.COLUMN_MEAN, [data["m10"]]), _rliable(data["m10"], lambda x: np.mean(x, axis=0)))


def test_poi_equal_rliable_with_ties_and_unequal_runs(data):
    def ref(x, y):
        return np.array([metrics.probability_of_improvement(x, y)])

    _equal(_ours(bs.PROBABILITY_OF_IMPROVEMENT, [data["m6"], data["y6"]], reps=60),
           _rliable([data["m6"], data["y6"]], ref, reps=60))
    # several numbers of runs: the interleaved, rejected stream; ties count a half
    _equal(_ours(bs.PROBABILITY_OF_IMPROVEMENT, [data["x5"], data["ties"]], reps=60),
           _rliable([data["x5"], data["ties"]], ref, reps=60))


def test_mixed_runs_and_one_run_matrix_equal_rliable(data):
    cols = [data["x5"][:, :1], data["y7"][:, :1], data["x5"][:, 1:2], data["ties"][:, :1]]

    def ref(a, *bs_):
        return np.array([np.mean(a) / np.mean([np.mean(b) for b in bs_])])

    # a one-run numerator draws nothing; the denominators interleave bounds 5, 7, 5, 4
    _equal(_ours(bs.RATIO_TO_TASK_MEANS, [data["one"], *cols]), _rliable([data["one"], *cols], ref))
    _equal(_ours(bs.DIFFERENCE_OF_MEANS, [data["x5"], data["y7"]]),
           _rliable([data["x5"], data["y7"]], lambda u, v: np.array([np.mean(u) - np.mean(v)])))


def test_chunks_continue_the_stream(data):
    """Repetitions drawn in many small chunks are those of one chunk (same stream, carried-over words)."""
    for stat, arrays in ((bs.COLUMN_MEAN, [data["m6"]]), (bs.DIFFERENCE_OF_MEANS, [data["x5"], data["y7"]])):
        whole = bs.bootstrap_values(stat, arrays, 250, 5)
        small = bs.bootstrap_values(stat, arrays, 250, 5, chunk_elements=40)
        np.testing.assert_array_equal(whole, small)


def test_performance_profile_equal_rliable(data):
    taus = np.linspace(0.0, 1.2, 7)
    with seeded(2):
        profiles, cis = rly.create_performance_profile({"k": data["m6"]}, taus, reps=REPS)
    ours = stats.performance_profiles({"k": data["m6"]}, taus, reps=REPS, seed=2)["k"]
    np.testing.assert_array_equal(ours[0], profiles["k"])
    np.testing.assert_array_equal(ours[1], cis["k"])


def test_stats_api_equal_rliable(data):
    """analysis.stats' public intervals are rliable's (the functions the tables, figures and claims call)."""
    x, y = data["m6"], data["y6"]
    ref = _rliable([x, y], lambda a, b: np.array([np.mean(a) / np.mean(b)]), seed=4)
    assert stats.ratio_of_means(x, y, reps=REPS, seed=4) == (ref[0][0], ref[1][0][0], ref[1][1][0])
    cis = stats.mean_cis([data["m10"][:, 0], data["m10"][:, 1], np.array([1.0])], reps=REPS, seed=3)
    ref = _rliable(data["m10"][:, :2], lambda a: np.mean(a, axis=0))
    assert cis[:2] == [(ref[1][0][0], ref[1][1][0]), (ref[1][0][1], ref[1][1][1])]
    assert np.isnan(cis[2]).all()


def test_intervals_of_every_draw_are_each_draws_own_bit_for_bit():
    """The power simulation's CIs of every draw at once (bootstrap.draw_intervals: a rule's statistic with a leading
    draws axis) are interval_estimates of each draw's data, bit for bit: the same indices, the same reductions, so a
    claim's rule judges one draw (the runs) as it judges that draw among many; one task, several, a statistic of two
    arrays, and one draw (interval_estimates itself)."""
    rng = np.random.default_rng(5)
    cases = [(bs.MEAN, [(6, 12)]), (bs.MEAN, [(13, 5)]), (bs.MEAN, [(20, 1)]), (bs.MEAN, [(1, 4)]),
             (bs.RATIO_OF_MEANS, [(6, 9), (4, 9)])]
    for stat, shapes in cases:
        for draws in (1, 7):
            arrays = [rng.normal(40.0, 30.0, size=(draws, *shape)) for shape in shapes]
            points, cis = bs.draw_intervals(stat, arrays, 301, 11)
            for d in range(draws):
                point, ci = bs.interval_estimates(stat, [a[d] for a in arrays], 301, 11)
                assert np.array_equal(points[d], point) and np.array_equal(cis[:, d], ci), (stat.name, shapes, d)
    means, lows, highs = stats.grand_mean_cis(rng.normal(size=(3, 6, 12)), 0, 1)  # no repetitions: the means alone
    assert np.isfinite(means).all() and np.isnan(lows).all() and np.isnan(highs).all()


def test_indices_are_drawn_once_per_shapes_and_reused_equal(monkeypatch: pytest.MonkeyPatch) -> None:
    """The second interval of the same shapes, random state and repetitions draws nothing and resamples with the
    indices a fresh stream draws (so its interval is rliable's too); other shapes or another state draw again; an
    entry over a quarter of the memo's bytes is not kept."""
    monkeypatch.setattr(bs, "_INDICES", bs._IndexMemo(bs.INDEX_MEMO_BYTES))
    fresh = bs.IndexStream([(6, 3)], 5).take(3000)[0]
    takes: list[tuple] = []
    real_take = bs.IndexStream.take
    monkeypatch.setattr(bs.IndexStream, "take", lambda self, reps: takes.append(tuple(self.shapes)) or
                        real_take(self, reps))
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
    first = bs.interval_estimates(bs.MEAN, [x], 3000, seed=5)
    drawn = len(takes)
    second = bs.interval_estimates(bs.MEAN, [y], 3000, seed=5)
    assert drawn >= 1 and len(takes) == drawn  # nothing drawn again
    assert np.array_equal(second[1], bs.percentile_cis(bs.MEAN.vector(y[fresh, np.arange(3)])))
    assert not np.array_equal(first[1], second[1])
    _equal(second, _rliable(y, lambda s: np.array([metrics.aggregate_mean(s)]), reps=3000, seed=5))
    bs.interval_estimates(bs.MEAN, [y], 3000, seed=6)
    bs.interval_estimates(bs.MEAN, [y[:5]], 3000, seed=5)
    assert len(takes) == drawn + 2
    monkeypatch.setattr(bs, "_INDICES", bs._IndexMemo(4 * 3000 * 18 - 1))  # a quarter is one byte short
    bs.interval_estimates(bs.MEAN, [x + 1.0], 3000, seed=5)
    bs.interval_estimates(bs.MEAN, [x + 2.0], 3000, seed=5)
    assert len(takes) == drawn + 4
