"""rliable's stratified bootstrap as whole-array operations: every repetition's indices drawn at once, the
statistic computed over a leading repetition axis, the percentile interval read from all repetitions.

rliable (``rliable.library.get_interval_estimates`` with arch's ``IIDBootstrap.conf_int``) runs one Python
iteration per repetition: it draws each repetition's indices with NumPy's legacy global generator
(``np.random.choice(n_runs, (n_runs, n_tasks))`` for a matrix; for a list of matrices, one such draw per matrix
in the list's order), resamples each task's column over its own runs, calls the statistic, and takes the
``100 * alpha`` and ``100 * (1 - alpha)`` percentiles of the results. Here:

* **Indices.** The same stream from a ``RandomState(seed)``: one ``randint(0, n, ...)`` over all repetitions of a
  chunk when every resampled matrix has the same number of runs ``n`` (``choice`` draws ``randint``; one
  draw of many values is the values of many draws, in order); otherwise the stream of 32-bit words that
  ``randint`` consumes, masked and rejected as it does (a bounded draw takes the next word ANDed with the
  smallest all-ones mask above ``n - 1`` until it is below ``n``), each repetition's segments located by a walk
  from repetition to repetition over the accepted words' counts (:meth:`IndexStream._locate`). A matrix of one run
  draws nothing,
  as in NumPy. So the indices, and with the statistics below the intervals, are rliable's bit for bit
  (tests/test_bootstrap.py checks both kinds against rliable itself).
* **Statistics.** :class:`Statistic` ``vector(*arrays)`` takes arrays of shape (reps, runs, tasks) and returns
  (reps, k); each reduces in the order NumPy reduces rliable's per-repetition call, so the values are equal.
* **Memory.** Repetitions go in chunks of at most :data:`CHUNK_ELEMENTS` resampled values (a statistic may say
  it needs more per value, e.g. the pairwise probability of improvement).
"""

from __future__ import annotations

import hashlib
import math
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from analysis.cache import lookup

CI_SIZE = 0.95
CHUNK_ELEMENTS = 4_000_000  # resampled values per chunk (~32 MB of float64, plus the same of indices)
# 32-bit words per chunk of the several-bounds stream: its walk keeps about 15 bytes per word and bound
MIXED_WORDS = 1_000_000
DRAW_ELEMENTS = 250_000  # resampled values per group of draws in draw_intervals (about 2 MB: cached, faster)
ESTIMATOR = ("analysis/bootstrap.py: rliable's stratified bootstrap and percentile interval as whole-array "
             "operations, equal to rliable's get_interval_estimates for the same random state")


@dataclass(frozen=True)
class Statistic:
    """A statistic of one or more (runs x tasks) matrices, computed for many repetitions at once.

    ``vector(*arrays)``: arrays of shape (reps, runs_i, tasks_i), returns (reps, k). ``cost``: temporary values
    per resampled value (bounds the chunk). ``key``: what, besides the name, the statistic depends on (the
    cache of intervals tells statistics apart by both)."""

    name: str
    vector: Callable[..., np.ndarray]
    cost: int = 1
    key: str = ""

    def point(self, *arrays: np.ndarray) -> np.ndarray:
        """The statistic of the data itself (k values), as rliable's point estimate."""
        return self.vector(*(a[None] for a in arrays))[0]


def _mean_all(x: np.ndarray) -> np.ndarray:
    """Mean over everything but the repetition axis, summed as np.mean sums one contiguous matrix."""
    return x.reshape(x.shape[0], -1).mean(axis=1)


def _task_means_mean(x: np.ndarray) -> np.ndarray:
    """rliable's aggregate_mean: the mean over tasks of each task's mean over runs."""
    return x.mean(axis=1).mean(axis=1)


def _iqm(x: np.ndarray) -> np.ndarray:
    """scipy.stats.trim_mean(x, 0.25, axis=None) per repetition (rliable's aggregate_iqm): the same partition of
    each flattened repetition, then the mean of its middle."""
    flat = x.reshape(x.shape[0], -1)
    n = flat.shape[1]
    low = int(0.25 * n)
    high = n - low
    part = np.partition(flat, (low, high - 1), axis=1)
    return part[:, low:high].mean(axis=1)


def _optimality_gap(x: np.ndarray, gamma: float = 1.0) -> np.ndarray:
    return gamma - _mean_all(np.minimum(x, gamma))


def _median(x: np.ndarray) -> np.ndarray:
    return np.median(x.mean(axis=1), axis=1)


def _pairwise_poi(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """rliable's probability_of_improvement per repetition: per task, the Mann-Whitney U of X over Y (pairs X > Y,
    ties a half) divided by m x n; the mean over tasks."""
    diff = x[:, :, None, :] - y[:, None, :, :]  # (reps, m, n, tasks)
    per_task = ((diff > 0).sum(axis=(1, 2)) + 0.5 * (diff == 0).sum(axis=(1, 2))) / (x.shape[1] * y.shape[1])
    return per_task.mean(axis=1)


def _col(f: Callable[..., np.ndarray]) -> Callable[..., np.ndarray]:
    return lambda *a: f(*a)[:, None]


COLUMN_MEAN = Statistic("column mean", lambda x: x.mean(axis=1))
MEAN = Statistic("mean", _col(_task_means_mean))
MEDIAN = Statistic("median", _col(_median))
IQM = Statistic("IQM", _col(_iqm))
OPTIMALITY_GAP = Statistic("optimality gap", _col(_optimality_gap))
AGGREGATES = Statistic("IQM, mean, optimality gap",
                       lambda x: np.stack([_iqm(x), _task_means_mean(x), _optimality_gap(x)], axis=1))
PROBABILITY_OF_IMPROVEMENT = Statistic("probability of improvement", _col(_pairwise_poi), cost=0)
RATIO_OF_MEANS = Statistic("ratio of means", _col(lambda a, b: _mean_all(a) / _mean_all(b)))
DIFFERENCE_OF_MEANS = Statistic("difference of means", _col(lambda a, b: _mean_all(a) - _mean_all(b)))
RATIO_TO_TASK_MEANS = Statistic(
    "ratio to the mean of task means",
    _col(lambda a, *bs: _mean_all(a) / np.stack([_mean_all(b) for b in bs], axis=1).mean(axis=1)))


def score_distribution(taus: np.ndarray) -> Statistic:
    """rliable's run-score performance profile: the fraction of all runs' scores above each tau."""
    t = np.asarray(taus, dtype=float)

    def vector(x: np.ndarray) -> np.ndarray:
        flat = x.reshape(x.shape[0], 1, -1)
        return (flat > t[None, :, None]).mean(axis=2)

    return Statistic("score distribution", vector, cost=len(t), key=t.tobytes().hex())


def _mask(bound: int) -> int:
    """The smallest all-ones mask at or above ``bound - 1`` (NumPy's bounded draws)."""
    return (1 << int(bound - 1).bit_length()) - 1


class IndexStream:
    """Each repetition's run indices for matrices of (runs, tasks) ``shapes``, drawn as rliable draws them from
    the legacy generator seeded with ``seed``, chunk by chunk."""

    def __init__(self, shapes: Sequence[tuple[int, int]], seed: int) -> None:
        self.shapes = [(int(n), int(m)) for n, m in shapes]
        if any(n < 1 or m < 1 for n, m in self.shapes):
            raise ValueError(f"every matrix needs at least one run and one task: {self.shapes}")
        self.rs = np.random.RandomState(seed)
        # consecutive matrices of the same bound draw as one; a matrix of one run draws nothing
        self.groups: list[tuple[int, int]] = []  # (bound, values per repetition)
        for n, m in self.shapes:
            if n == 1:
                continue
            if self.groups and self.groups[-1][0] == n:
                self.groups[-1] = (n, self.groups[-1][1] + n * m)
            else:
                self.groups.append((n, n * m))
        self.words = np.zeros(0, dtype=np.uint32)  # drawn 32-bit words not used yet (several bounds)

    @property
    def per_rep(self) -> int:
        return sum(n * m for n, m in self.shapes)

    @property
    def mixed(self) -> bool:
        """Whether several numbers of runs interleave (the masked-and-rejected stream)."""
        return len({b for b, _ in self.groups}) > 1

    @property
    def words_per_rep(self) -> int:
        """32-bit words one repetition consumes on average (a bounded draw rejects what its mask exceeds)."""
        return math.ceil(sum(c * (_mask(b) + 1) / b for b, c in self.groups))

    def take(self, reps: int) -> list[np.ndarray]:
        """The next ``reps`` repetitions' indices: one (reps, runs, tasks) array per matrix."""
        if not self.mixed:
            drawn = [self.rs.randint(0, b, size=(reps, c)) for b, c in self.groups]
        else:
            drawn = self._take_mixed(reps)
        out, it, group_pos = [], iter(zip(drawn, self.groups)), 0
        current: np.ndarray | None = None
        for n, m in self.shapes:
            if n == 1:
                out.append(np.zeros((reps, 1, m), dtype=np.int64))
                continue
            if current is None or group_pos >= current.shape[1]:
                current, _ = next(it)
                group_pos = 0
            out.append(current[:, group_pos:group_pos + n * m].reshape(reps, n, m))
            group_pos += n * m
        return out

    def _take_mixed(self, reps: int) -> list[np.ndarray]:
        """Several bounds interleaved: the words ``randint`` would consume, masked and rejected in place."""
        size = int(reps * self.words_per_rep * 1.1) + 64
        while True:
            if len(self.words) < size:
                more = self.rs.randint(0, 2**32, size=size - len(self.words), dtype=np.uint32)
                self.words = np.concatenate([self.words, more])
            result = self._locate(reps)
            if result is not None:
                return result
            size *= 2

    def _locate(self, reps: int) -> list[np.ndarray] | None:
        """The next ``reps`` repetitions' indices from :attr:`words` (None when they run out first): each group's
        accepted words counted before every position, then a walk from one repetition's start to the next (a group
        of ``count`` draws from position p ends after its accepted word number ``accepted_before[p] + count``),
        one step per repetition and group, then every repetition's words gathered at once."""
        words = self.words
        total = len(words)
        values, accepted, cums = [], [], []
        for bound, _ in self.groups:
            masked = words & np.uint32(_mask(bound))
            ok = masked < bound
            cum = np.zeros(total + 1, dtype=np.int32)  # accepted words before each position (a chunk's words fit)
            np.cumsum(ok, out=cum[1:])
            values.append(masked)
            accepted.append(np.flatnonzero(ok).astype(np.int32))
            cums.append(cum)
        starts = np.empty(reps, dtype=np.int64)
        walk = [(cum.item, acc.item, len(acc), count) for cum, acc, (_, count) in zip(cums, accepted, self.groups)]
        position = 0
        for rep in range(reps):
            starts[rep] = position
            for before, word, available, count in walk:
                last = before(position) + count - 1
                if last >= available:
                    return None
                position = word(last) + 1
        out = []
        group_start: np.ndarray = starts
        for (_, count), masked, acc, cum in zip(self.groups, values, accepted, cums):
            first = cum[group_start]
            where = acc[first[:, None] + np.arange(count)]
            out.append(masked[where].astype(np.int64))
            group_start = where[:, -1] + 1
        self.words = words[position:]
        return out


def resample(arrays: Sequence[np.ndarray], cells: Sequence[np.ndarray]) -> list[np.ndarray]:
    """Each array's tasks resampled over its own runs: out[r, i, j] = array.flat[cells[r, i, j]], where
    cells[r, i, j] = idx[r, i, j] * tasks + j for the run idx[r, i, j] drawn (:func:`index_chunks`): one index per
    value, several times faster than indexing rows and columns, array[idx, arange(tasks)], with the same values."""
    return [np.ascontiguousarray(a).reshape(-1)[cell] for a, cell in zip(arrays, cells)]


def index_chunks(stat: Statistic, arrays: Sequence[np.ndarray], reps: int, seed: int,
                 chunk_elements: int = CHUNK_ELEMENTS) -> Iterator[list[np.ndarray]]:
    """The bootstrap indices of ``reps`` repetitions of ``arrays`` (their shapes), chunk by chunk: each chunk one
    (repetitions, runs, tasks) array per matrix of the drawn values' places in the flattened matrix, run * tasks + task
    for the run :meth:`IndexStream.take` draws (:func:`resample`), in the smallest unsigned type that holds them.
    They depend only on the shapes, the random state and the chunking, so a command draws them once per such key
    (:data:`_INDICES`): a report asks for the same shapes dozens of times (every cell of six seeds, every
    learning-curve point)."""
    stream = IndexStream([a.shape for a in arrays], seed)
    per_rep = stream.per_rep * max(1, stat.cost if stat.cost else _pairs(arrays))
    chunk = max(1, chunk_elements // per_rep)
    if stream.mixed:
        chunk = max(1, min(chunk, MIXED_WORDS // max(1, stream.words_per_rep)))
    key = (tuple(stream.shapes), int(seed), int(reps), chunk)
    kept = _INDICES.get(key)
    if kept is not None:
        _INDICES.move_to_end(key)
        yield from kept
        return
    types = [np.min_scalar_type(n * m - 1) for n, m in stream.shapes]
    # kept, each chunk as it is drawn, when the whole fits the memo
    size = reps * sum(n * m * t.itemsize for (n, m), t in zip(stream.shapes, types))
    drawn: list[list[np.ndarray]] | None = [] if _INDICES.fits(size) else None
    done = 0
    while done < reps:
        b = min(chunk, reps - done)
        part = [_cells(idx, m, t) for idx, (_, m), t in zip(stream.take(b), stream.shapes, types)]
        if drawn is not None:
            drawn.append(part)
        yield part
        done += b
    if drawn is not None:
        _INDICES.keep(key, drawn)


def _cells(runs: np.ndarray, tasks: int, kind: np.dtype) -> np.ndarray:
    """The drawn ``runs`` (reps, runs, tasks) as places in the flattened matrix, run * tasks + task, of type
    ``kind``, read-only."""
    cells = runs * tasks  # a new array, whatever ``tasks``
    cells += np.arange(tasks)
    cells = cells.astype(kind, copy=False)
    cells.flags.writeable = False  # kept in the memo and handed to every later caller
    return cells


class _IndexMemo(OrderedDict):
    """Drawn bootstrap indices by (shapes, random state, repetitions, chunk), the least recently used dropped beyond
    :data:`INDEX_MEMO_BYTES`; an entry over a quarter of it is not kept."""

    def __init__(self, limit: int) -> None:
        super().__init__()
        self.limit, self.bytes = limit, 0

    def fits(self, size: int) -> bool:
        return size <= self.limit // 4

    def keep(self, key: tuple, chunks: list[list[np.ndarray]]) -> None:
        self[key] = chunks
        self.bytes += _nbytes(chunks)
        while self.bytes > self.limit:
            _, old = self.popitem(last=False)
            self.bytes -= _nbytes(old)


def _nbytes(chunks: list[list[np.ndarray]]) -> int:
    return sum(idx.nbytes for part in chunks for idx in part)


INDEX_MEMO_BYTES = 64_000_000  # indices kept for reuse within one process (at most a quarter of it per key)
_INDICES = _IndexMemo(INDEX_MEMO_BYTES)


def values_from(stat: Statistic, arrays: Sequence[np.ndarray], chunks: Iterable[list[np.ndarray]]) -> np.ndarray:
    """The statistic at each repetition of the index ``chunks`` (:func:`index_chunks`): (reps, k)."""
    parts = [stat.vector(*resample(arrays, idx)) for idx in chunks]
    return np.concatenate(parts).astype(float, copy=False)


def bootstrap_values(stat: Statistic, arrays: Sequence[np.ndarray], reps: int, seed: int,
                     chunk_elements: int = CHUNK_ELEMENTS) -> np.ndarray:
    """The statistic at each of ``reps`` repetitions: (reps, k)."""
    return values_from(stat, arrays, index_chunks(stat, arrays, reps, seed, chunk_elements))


def percentile_cis(values: np.ndarray, size: float = CI_SIZE) -> np.ndarray:
    """The percentile interval of bootstrap ``values`` (reps, k): (2, k)."""
    alpha = (1.0 - size) / 2
    return np.percentile(values, [100 * alpha, 100 * (1.0 - alpha)], axis=0)


def draw_intervals(stat: Statistic, arrays: Sequence[np.ndarray], reps: int, seed: int,
                   size: float = CI_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """:func:`interval_estimates` of every draw: ``arrays`` with a leading draws axis, each (draws, runs, tasks);
    returns the points (draws, k) and the CIs (2, draws, k). One draw is :func:`interval_estimates` itself (its
    cache); several resample every draw with the same indices (they depend only on the shapes and the random state,
    so they are drawn once, :func:`index_chunks`) and compute the statistic over (draws x repetitions) at once, each
    draw's values reduced as its own call reduces them: each draw's interval equals :func:`interval_estimates` of its
    data bit for bit (tests/test_bootstrap.py)."""
    mats = [np.ascontiguousarray(a, dtype=float) for a in arrays]
    if any(a.ndim != 3 for a in mats):
        raise ValueError("draw_intervals takes (draws x runs x tasks) arrays")
    draws = mats[0].shape[0]
    if draws == 1:
        point, cis = interval_estimates(stat, [a[0] for a in mats], reps, seed, size)
        return point[None], cis[:, None]
    points = stat.vector(*mats)
    values = np.empty((draws, reps, points.shape[1]))
    flats = [a.reshape(draws, -1) for a in mats]
    done = 0
    by_run = stat is MEAN and mats[0].shape[2] > 1
    for cells in index_chunks(stat, [a[0] for a in mats], reps, seed):
        b = cells[0].shape[0]
        # draws resampled at once: by run, a chunk's (reps, tasks) means of them all; else what stays in cache
        per_draw = b * sum(c[0].size for c in cells) // (cells[0].shape[1] if by_run else 1)
        group = max(1, (CHUNK_ELEMENTS if by_run else DRAW_ELEMENTS) // max(1, per_draw))
        for d in range(0, draws, group):
            if by_run:
                values[d:d + group, done:done + b, 0] = _mean_by_run(flats[0][d:d + group], cells[0])
                continue
            part = [f[d:d + group][:, c].reshape(-1, *c.shape[1:]) for f, c in zip(flats, cells)]
            values[d:d + group, done:done + b] = stat.vector(*part).reshape(-1, b, points.shape[1])
        done += b
    alpha = (1.0 - size) / 2
    return points, np.percentile(values, [100 * alpha, 100 * (1.0 - alpha)], axis=1)


def _mean_by_run(flat: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """:data:`MEAN` of every draw's resampled matrices: ``flat`` (draws, runs * tasks) each draw's matrix, ``cells``
    (reps, runs, tasks) the drawn places (:func:`index_chunks`); (draws, reps). With several tasks NumPy's mean over
    the runs (a middle axis) adds them in order, so adding the drawn runs one by one, every draw's value of a drawn
    place at once, gives the same values without the reduction's short inner loops (tests/test_bootstrap.py: equal to
    :func:`interval_estimates`); the mean over the tasks is then MEAN's call, on a (reps, tasks) matrix (NumPy sums a
    3-D array's last axis otherwise)."""
    idx = cells.astype(np.intp)
    runs = idx.shape[1]
    by_place = np.ascontiguousarray(flat.T)  # (runs * tasks, draws): a drawn place is one row of every draw's value
    total = by_place[idx[:, 0, :]]  # (reps, tasks, draws): a new array
    for i in range(1, runs):
        total += by_place[idx[:, i, :]]
    total /= runs
    means = np.ascontiguousarray(total.transpose(2, 0, 1))  # (draws, reps, tasks)
    return means.reshape(-1, idx.shape[2]).mean(axis=1).reshape(means.shape[:2])  # as MEAN's (reps, tasks) mean


def _pairs(arrays: Sequence[np.ndarray]) -> int:
    """Temporary values per resampled value of the pairwise statistics (runs of X x runs of Y)."""
    return max(a.shape[0] for a in arrays)


def interval_estimates(stat: Statistic, arrays: Sequence[np.ndarray], reps: int, seed: int,
                       size: float = CI_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """(point estimates (k,), CIs (2, k)): the statistic of the data and the percentile interval of its
    stratified bootstrap, as ``rliable.library.get_interval_estimates(..., method='percentile')``."""
    mats = [np.ascontiguousarray(a, dtype=float) for a in arrays]
    if any(a.ndim != 2 for a in mats):
        raise ValueError("the bootstrap takes (runs x tasks) matrices")
    h = hashlib.sha1(f"{stat.name}|{stat.key}|{reps}|{seed}|{size!r}".encode())
    for a in mats:
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())

    def compute() -> tuple[np.ndarray, np.ndarray]:
        return stat.point(*mats), percentile_cis(bootstrap_values(stat, mats, reps, seed), size)

    point, cis = lookup("intervals", h.hexdigest(), compute)  # the same interval is computed once (analysis/cache.py)
    return point.copy(), cis.copy()


def nan_interval(k: int = 1) -> np.ndarray:
    return np.full((2, k), math.nan)
