"""Parameter sets of a sweep: a full grid, a table of samples, or a sampler (Latin
hypercube, Sobol, uniform random; ``scipy.stats.qmc``, seeded) within bounds.

A :class:`Samples` is a table: ``names`` (the parameters) and ``values``, one row per run.
A sweep has at most :data:`MAX_RUNS` runs: a larger grid or sample is refused before it is
built (its table alone would take gigabytes, its summary more).
"""
from __future__ import annotations

import itertools
import math

import numpy as np

from ncgen.errors import NcgenError, option

#: Most runs of one sweep (a grid's or sampler's size is checked against it before building).
MAX_RUNS = 10**7


class Samples:
    """Rows of parameter values, one per run (``values``: runs × ``len(names)``)."""

    def __init__(self, names, values):
        self.names = [str(n) for n in names]
        values = np.array(values, dtype=float)
        self.values = values.reshape(len(values), len(self.names)) if values.ndim == 2 else \
            values.reshape(-1, len(self.names))
        if len(set(self.names)) != len(self.names):
            raise NcgenError(f"samples: a parameter is named twice in {self.names}")
        if not np.all(np.isfinite(self.values)):
            row, col = np.argwhere(~np.isfinite(self.values))[0]
            raise NcgenError(f"samples: run {row} has a non-finite value of {self.names[col]!r}")

    def __len__(self) -> int:
        return len(self.values)

    def __repr__(self) -> str:
        return f"<Samples: {len(self)} runs of {', '.join(self.names)}>"

    def column(self, name: str) -> np.ndarray:
        return self.values[:, self.names.index(name)]

    # ------------------------------------------------------------ constructors
    @classmethod
    def grid(cls, axes: dict) -> "Samples":
        """Every combination of the values of ``axes`` (``{name: values}``), the last name
        varying fastest."""
        names = list(axes)
        levels = []
        for name in names:
            try:
                v = np.atleast_1d(np.asarray(axes[name], dtype=float))
            except (TypeError, ValueError):
                v = np.zeros((0, 0))
            if v.ndim != 1 or not len(v):
                raise NcgenError(f"grid: parameter {name!r}: expected a non-empty list of numbers, got {axes[name]!r}")
            if not np.all(np.isfinite(v)):
                raise NcgenError(f"grid: parameter {name!r}: expected finite numbers, got {v[~np.isfinite(v)][0]}")
            levels.append(v)
        size = math.prod(len(v) for v in levels)
        if size > MAX_RUNS:
            counts = " × ".join(f"{len(v)} ({n})" for n, v in zip(names, levels))
            raise NcgenError(f"grid: {counts} = {size:.3g} runs, more than the limit of {MAX_RUNS:.0e}; "
                             "use fewer values or a sampler (nc.Samples.latin_hypercube)")
        return cls(names, np.array(list(itertools.product(*levels))).reshape(-1, len(names)))

    @classmethod
    def table(cls, data) -> "Samples":
        """One run per row of ``data``: a pandas DataFrame, or a dict of equal-length arrays."""
        if hasattr(data, "columns") and hasattr(data, "to_numpy"):
            return cls(list(data.columns), data.to_numpy(dtype=float))
        if not isinstance(data, dict) or not data:
            raise NcgenError(f"samples table: expected a pandas DataFrame or a dict of equal-length arrays, got "
                             f"{type(data).__name__}")
        columns = {k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in data.items()}
        lengths = {k: len(v) for k, v in columns.items()}
        if len(set(lengths.values())) != 1:
            raise NcgenError(f"samples table: the columns differ in length ({lengths})")
        return cls(list(columns), np.column_stack(list(columns.values())))

    @classmethod
    def latin_hypercube(cls, n: int, bounds: dict, seed=None) -> "Samples":
        """``n`` runs, a Latin hypercube in the box ``bounds`` = ``{name: (low, high)}``."""
        names, low, high = _bounds(bounds)
        n = _count(n)                           # refused before SciPy's seconds of importing
        from scipy.stats import qmc
        return cls(names, qmc.scale(qmc.LatinHypercube(d=len(names), seed=_seed(seed)).random(n), low, high))

    @classmethod
    def sobol(cls, n: int, bounds: dict, seed=None) -> "Samples":
        """``n`` runs (a power of two keeps the sequence balanced), scrambled Sobol points in ``bounds``."""
        names, low, high = _bounds(bounds)
        n = _count(n)
        if n & (n - 1):
            raise NcgenError(f"sobol: n = {n}: expected a power of two (Sobol points are balanced only then); "
                             f"e.g. {1 << (n - 1).bit_length()}")
        from scipy.stats import qmc
        return cls(names, qmc.scale(qmc.Sobol(d=len(names), seed=_seed(seed)).random(n), low, high))

    @classmethod
    def random(cls, n: int, bounds: dict, seed=None) -> "Samples":
        """``n`` runs drawn uniformly in ``bounds`` (NumPy's default generator, ``seed``)."""
        names, low, high = _bounds(bounds)
        return cls(names, np.random.default_rng(_seed(seed)).uniform(low, high, size=(_count(n), len(names))))


def as_samples(params) -> Samples:
    """``params`` of a sweep as :class:`Samples`: Samples as they are, a DataFrame as a
    table, a dict as a full grid."""
    if isinstance(params, Samples):
        return params
    if hasattr(params, "columns") and hasattr(params, "to_numpy"):
        return Samples.table(params)
    if isinstance(params, dict):
        return Samples.grid(params)
    raise NcgenError(f"params: expected a dict of values (full grid), a pandas DataFrame or nc.Samples (a table "
                     f"or a sampler), got {type(params).__name__}")


def _bounds(bounds: dict):
    if not isinstance(bounds, dict) or not bounds:
        raise NcgenError(f"bounds: expected {{name: (low, high)}}, got {bounds!r}")
    names, low, high = [], [], []
    for name, b in bounds.items():
        try:
            lo, hi = (float(x) for x in b)
        except (TypeError, ValueError):
            raise NcgenError(f"bounds of {name!r}: expected (low, high), got {b!r}") from None
        if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
            raise NcgenError(f"bounds of {name!r}: expected finite low < high, got ({lo}, {hi})")
        names.append(name), low.append(lo), high.append(hi)
    return names, np.array(low), np.array(high)


def _seed(seed):
    """``seed`` as the samplers take it: None, an integer >= 0, or a NumPy ``Generator`` or
    ``SeedSequence`` as it is."""
    if seed is None or isinstance(seed, (np.random.Generator, np.random.SeedSequence)):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise NcgenError(f"{option('seed', '--seed')}: expected None or an integer >= 0 (the same seed draws the "
                         f"same runs), got {seed!r}")
    return int(seed)


def _count(n) -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer, float)) or not math.isfinite(n) \
            or int(n) != n or n < 1:
        raise NcgenError(f"n: expected a positive number of runs, got {n!r}")
    if n > MAX_RUNS:
        raise NcgenError(f"n: {int(n):.3g} runs, more than the limit of {MAX_RUNS:.0e} runs of one sweep")
    return int(n)
