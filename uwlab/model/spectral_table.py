"""Fast, accurate evaluation of the chain's spectral integrals at any number of path lengths.

Every spectral integral of the chain has the form F(D) = Σ_j w_j e^(−γ_j D) with w_j ≥ 0: on the optical axis
G(D) = Σ_λ W(λ) e^(−c(λ) D) (trapezoidal weights W, attenuating path D = scale · distance; see
`uwlab.model.design`), and over the image a sum of such terms with rates c(λ)/cos α_w. Such a function is a
Laplace transform of a positive measure, so ln F is smooth and convex, and its n-th derivative is the n-th
cumulant of the rates under the measure tilted by e^(−γD) (bounded by the spread of the rates).

`LogHermiteTable` tabulates ln F and d ln F / dD on nodes and interpolates with cubic Hermite polynomials
(Fritsch & Carlson, SIAM J. Numer. Anal. 17 (1980) 238, eq. 2.1 form). Its nodes lie on a fixed lattice
independent of the points asked for, so a point's value never depends on the grid it is evaluated in (a chunk
of a grid, or a Dask worker, gives the same bits as the whole grid): blocks [0, L), [L, 2L), [2L, 4L), ..., each
split into equal intervals, halved until the interpolant matches F at every interval midpoint (where the cubic
Hermite error peaks) within `TOLERANCE` in ln F, i.e. relative error in F. A point then costs a few array
operations instead of a sum over the wavelength grid, whatever the shape of the grid.

Nodes are computed with one matrix product over wavelength per block: e^(−D ⊗ γ) @ w, scaled by e^(γ_min D)
so that neither underflows at long paths.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

TOLERANCE = 1e-9
FIRST_INTERVALS = 64
MAX_INTERVALS = 1 << 16
PIECE = 1 << 15  # points per lookup pass (keeps the temporaries in cache)


class LogHermiteTable:
    """A positive function F(D) of D ≥ 0 with `columns` components, tabulated as ln F and d ln F/dD.

    `fn(D)` returns (ln F, d ln F/dD), each of shape D.shape + (columns,). `first_block` is the length L of the
    first block [0, L); later blocks double. `tolerance` bounds |ln F_interp − ln F| at interval midpoints.
    """

    def __init__(
        self,
        fn: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
        columns: int,
        first_block: float,
        tolerance: float = TOLERANCE,
    ):
        if not first_block > 0:
            raise ValueError("first_block must be > 0")
        self._fn = fn
        self.columns = columns
        self.first_block = float(first_block)
        self.tolerance = tolerance
        self._blocks: dict[int, tuple[float, float, np.ndarray]] = {}  # b → (start, step, coefficients (n, K, 4))
        self._packed = None

    def block_of(self, x: np.ndarray) -> np.ndarray:
        """Block index of each D: 0 on [0, L), b on [L 2^(b−1), L 2^b)."""
        with np.errstate(divide="ignore"):
            b = np.floor(np.log2(np.asarray(x, float) / self.first_block)) + 1
        return np.maximum(b, 0).astype(np.intp)

    def _bounds(self, b: int) -> tuple[float, float]:
        if b == 0:
            return 0.0, self.first_block
        return self.first_block * 2.0 ** (b - 1), self.first_block * 2.0**b

    def _build(self, b: int) -> None:
        start, stop = self._bounds(b)
        n = FIRST_INTERVALS
        x = np.linspace(start, stop, n + 1)
        y, dy = self._fn(x)
        while True:
            step = (stop - start) / n
            coef = _hermite_coefficients(y, dy, step)
            mid_y, mid_dy = self._fn(x[:-1] + step / 2)
            error = np.max(np.abs(_horner(np.moveaxis(coef, -1, 0), 0.5) - mid_y))
            if error <= self.tolerance or n >= MAX_INTERVALS:
                break
            x = np.linspace(start, stop, 2 * n + 1)
            y = _interleave(y, mid_y)
            dy = _interleave(dy, mid_dy)
            n *= 2
        if not error <= self.tolerance:
            raise ArithmeticError(f"spectral table did not reach {self.tolerance:g} on [{start:g}, {stop:g}] m")
        self._blocks[b] = (start, step, coef)
        self._packed = None

    def _pack(self):
        """Per block (start, step, first row, rows) and the coefficients as (columns, 4, rows): each column's
        four polynomial coefficients are contiguous, for fast gathers."""
        if self._packed is None:
            top = max(self._blocks) + 1
            start = np.full(top, np.nan)
            step = np.full(top, np.nan)
            offset = np.zeros(top, np.intp)
            count = np.zeros(top, np.intp)
            coefs, total = [], 0
            for b in sorted(self._blocks):
                start[b], step[b], coef = self._blocks[b]
                offset[b], count[b] = total, coef.shape[0]
                coefs.append(coef)
                total += coef.shape[0]
            packed = np.ascontiguousarray(np.concatenate(coefs).transpose(1, 2, 0))
            self._packed = (start, step, offset, count, packed)
        return self._packed

    def _ensure(self, x: np.ndarray) -> None:
        """Build the blocks covering [min x, max x]."""
        if not np.min(x) >= 0:
            raise ValueError("path lengths must be >= 0")
        lo, hi = int(self.block_of(np.min(x))), int(self.block_of(np.max(x)))
        for b in range(lo, hi + 1):
            if b not in self._blocks:
                self._build(b)

    def _rows(self, x: np.ndarray):
        """(row of each x's interval, position u ∈ [0, 1] in it, interval length); x 1-D inside built blocks."""
        start, step, offset, count, _ = self._pack()
        lo, hi = int(self.block_of(x.min())), int(self.block_of(x.max()))
        if lo == hi:
            t = x - start[lo]
            t /= step[lo]
            j = t.astype(np.intp)
            np.minimum(j, count[lo] - 1, out=j)
            t -= j
            j += offset[lo]
            return j, t, step[lo]
        b = np.clip(self.block_of(x), lo, hi)
        t = (x - start[b]) / step[b]
        j = np.minimum(np.maximum(t, 0).astype(np.intp), count[b] - 1)
        return j + offset[b], t - j, step[b]

    def _evaluate(self, x, column, value_of):
        """Apply `value_of(coefficient rows (4 arrays), u, step)` over x in cache-sized pieces; `column` is an
        int or, per point, an int array broadcast with x (counted from 0)."""
        x = np.asarray(x, float)
        per_point = np.ndim(column) > 0
        if per_point:
            x, column = np.broadcast_arrays(x, column)
            column = column.ravel()
        out = np.empty(x.shape)
        if x.size == 0:
            return out
        self._ensure(x)
        coef = self._pack()[4]
        rows = coef.shape[2]
        flat_x, flat_out = x.ravel(), out.reshape(-1)
        for s in range(0, flat_x.size, PIECE):
            j, u, step = self._rows(flat_x[s : s + PIECE])
            if per_point:
                j += column[s : s + PIECE] * (4 * rows)
                flat = coef.reshape(-1)
                c = [flat.take(j + i * rows) for i in range(4)]
            else:
                c = [coef[column, i].take(j) for i in range(4)]
            flat_out[s : s + PIECE] = value_of(c, u, step)
        return out

    def log(self, x, column: int) -> np.ndarray:
        """ln F of one column at x (any shape)."""
        return self._evaluate(x, column, lambda c, u, step: _horner(c, u))

    def log_slope(self, x, column: int) -> np.ndarray:
        """d ln F/dD of one column at x: the derivative of the interpolant."""
        return self._evaluate(x, column, lambda c, u, step: (c[1] + u * (2 * c[2] + 3 * u * c[3])) / step)

    def __call__(self, x, column: int) -> np.ndarray:
        """F of one column at x: exp of the interpolated ln F."""
        return self._evaluate(x, column, lambda c, u, step: _exp(_horner(c, u)))

    def at_columns(self, x, k) -> np.ndarray:
        """F_k(x) with a column number per point, counted from 1 (k = 0 gives 0); x and k broadcast."""
        k = np.asarray(k)
        value = self._evaluate(x, np.maximum(k, 1) - 1, lambda c, u, step: _exp(_horner(c, u)))
        return np.where(k > 0, value, 0.0)


def _exp(y: np.ndarray) -> np.ndarray:
    return np.exp(y, out=y)


def _interleave(a: np.ndarray, mid: np.ndarray) -> np.ndarray:
    out = np.empty((a.shape[0] + mid.shape[0],) + a.shape[1:], a.dtype)
    out[0::2] = a
    out[1::2] = mid
    return out


def _hermite_coefficients(y: np.ndarray, dy: np.ndarray, step: float) -> np.ndarray:
    """Per interval, (p0, m0, 3Δ − 2m0 − m1, m0 + m1 − 2Δ) with m = step · dy: p(u) = Σ c_i u^i on u ∈ [0, 1]."""
    p0, p1 = y[:-1], y[1:]
    m0, m1 = step * dy[:-1], step * dy[1:]
    delta = p1 - p0
    return np.stack([p0, m0, 3 * delta - 2 * m0 - m1, m0 + m1 - 2 * delta], axis=-1)


def _horner(c, u) -> np.ndarray:
    """c[0] + u (c[1] + u (c[2] + u c[3])) for a sequence of four coefficient arrays (or a leading axis of 4)."""
    y = c[3] * u
    y += c[2]
    y *= u
    y += c[1]
    y *= u
    y += c[0]
    return y


def exponential_sum_log(weights: np.ndarray, rates: np.ndarray):
    """(ln F, d ln F/dD) for F_k(D) = Σ_j weights[j, k] e^(−rates[j] D), as a function of D (1-D array).

    Columns whose weights are all zero have no logarithm; they are reported as ln F = 0 and must be masked by
    the caller (see `SpectralTable`).
    """
    weights = np.where(weights.any(axis=0), weights, 1.0)
    used = np.any(weights > 0, axis=1)
    weights = weights[used]
    floor = float(np.min(rates[used]))
    shifted = rates[used] - floor
    wr = weights * shifted[:, None]

    def fn(x: np.ndarray):
        e = np.exp(-np.multiply.outer(x, shifted))
        g = e @ weights
        return np.log(g) - floor * x[:, None], -(e @ wr) / g - floor

    return fn


class SpectralTable:
    """The path integrals G_k(D) = Σ_λ W_k(λ) e^(−c(λ) D) of `uwlab.model.design.SpectralWeights` (columns:
    target irradiance, sensor irradiance, electron rate, each per unit luminous flux), for any D ≥ 0.

    Exact (to `TOLERANCE` relative) without a sum over wavelength per point. Zero columns stay zero.
    """

    def __init__(self, c: np.ndarray, W: np.ndarray, tolerance: float = TOLERANCE):
        positive = W > 0
        used = positive.any(axis=1)
        self.rate_min = float(np.min(c[used])) if used.any() else 0.0
        self.rate_max = float(np.max(c[used])) if used.any() else 0.0
        spread = self.rate_max - self.rate_min
        self.nonzero = positive.any(axis=0)
        self.table = LogHermiteTable(exponential_sum_log(W, c), W.shape[1], _first_block(spread), tolerance)

    def __call__(self, path_m, column: int) -> np.ndarray:
        """G of one column (0 target irradiance, 1 sensor irradiance, 2 electron rate) at path lengths `path_m`."""
        return self.table(path_m, column) * self.nonzero[column]


def _first_block(spread_per_m: float) -> float:
    """First block length [m]: 64 intervals of 0.2/Δγ (refined when needed), within [1, 100] m."""
    return float(np.clip(FIRST_INTERVALS * 0.2 / spread_per_m, 1.0, 100.0)) if spread_per_m > 0 else 100.0


def image_table(
    spectral: SpectralTable, secants: np.ndarray, weights: np.ndarray, column: int = 2, tolerance: float = TOLERANCE
) -> LogHermiteTable:
    """H_k(D) = Σ_{i<k} weights_i G(D · secants_i), k = 1..n (cumulative over the samples in the given order).

    The image average of the chain sums the electron-rate integral G over image samples i whose paths are
    longer by sec α_w,i; with the samples sorted by field angle, the ones inside a beam of half-angle β are a
    prefix, so one table answers every beam angle (`LogHermiteTable.at_columns`).
    """
    secants = np.asarray(secants, float)
    weights = np.asarray(weights, float)

    def fn(x: np.ndarray):
        d = np.multiply.outer(x, secants)
        log_g, slope = spectral.table.log(d, column), spectral.table.log_slope(d, column)
        log_terms = log_g + np.log(weights)
        terms = np.exp(log_terms - log_terms[..., :1])  # the sample nearest the axis is the largest: no underflow
        sums = np.cumsum(terms, axis=-1)
        return np.log(sums) + log_terms[..., :1], np.cumsum(terms * slope * secants, axis=-1) / sums

    spread = spectral.rate_max * float(np.max(secants)) - spectral.rate_min
    return LogHermiteTable(fn, secants.size, _first_block(spread), tolerance)
