"""Two-dimensional CFAR detection on range-Doppler power maps.

Maps are ``[..., R, D]`` square-law power (``|x|**2``, summed over antennas if
wanted). Around each cell under test (CUT) the window has ``guard = (gr, gd)``
guard cells and, beyond them, ``train = (tr, td)`` training cells on each
side along range and Doppler: the training region is the
``(2(gr+tr)+1) x (2(gd+td)+1)`` box minus the ``(2gr+1) x (2gd+1)`` guard box,
``N`` cells in all.

Thresholds come from the requested false-alarm probability under i.i.d.
exponential noise (complex Gaussian noise after square-law detection):

- **CA** (cell averaging), noise = mean of the ``N`` cells,
  ``alpha = N * (Pfa**(-1/N) - 1)``.
- **SO / GO** (smallest-of / greatest-of), the ``N`` cells split into a
  *near* half (range offset < 0, plus the CUT's own row at Doppler offset < 0)
  and a *far* half (the mirror image), ``n = N/2`` cells each; noise = the
  smaller / larger half mean. With ``T = alpha / n`` applied to a half sum,
  ``Pfa_SO(T) = 2 * sum_{k<n} C(n-1+k, k) * (2+T)**-(n+k)`` and
  ``Pfa_GO(T) = 2 * (1+T)**-n - Pfa_SO(T)`` (exact for exponential noise;
  Gandhi & Kassam 1988); ``T`` is found by root finding on this formula.
- **OS** (ordered statistic), noise statistic = the ``k``-th smallest of the
  ``N`` cells (``os_rank``, default ``round(3N/4)``);
  ``Pfa = prod_{i<k} (N-i) / (N-i+alpha)`` (Rohling 1983), solved for alpha.

Box sums come from one summed-area table, so CA/SO/GO cost does not depend on
the window size. OS detection does not select ``X_(k)`` at every cell: it counts
the training cells below the CUT's level (exact, see :func:`_os_detect_kernel`),
about 15x cheaper than a per-cell selection. The full OS threshold and noise
maps of :class:`CfarResult` are then computed only when first read (compiled
per-cell selection; ``scipy.ndimage.rank_filter`` with a ring footprint is ~5x
slower still), and :meth:`CfarResult.noise_power_at` selects only at the cells
asked for (what :func:`detect` uses for the SNR of each detection).

Edges (``edge=``): the Doppler axis is circular (the DFT is), so it always wraps
except as stated:

- ``"wrap-doppler"`` (default): Doppler wraps; range is mirrored at both ends
  (``numpy.pad(mode="reflect")``), so the first/last ``gr + tr`` range rows
  reuse cells and their false-alarm rate is only approximately ``pfa``.
- ``"wrap"``: both axes circular.
- ``"valid-range"``: Doppler wraps; range rows whose window would leave the
  map are not tested (``mask`` False, ``threshold`` +inf, ``noise_power`` NaN).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from math import comb, log
from typing import Any

import numba
import numpy as np
import scipy.ndimage
import scipy.optimize

METHODS = ("ca", "so", "go", "os")
EDGES = ("wrap-doppler", "wrap", "valid-range")
#: :func:`cfar_2d`'s guard and training cells on each side of the CUT, (range, Doppler), unless given.
DEFAULT_GUARD = (2, 2)
DEFAULT_TRAIN = (8, 4)


@dataclass(frozen=True)
class CfarWindow:
    """Guard and training half-widths (cells on each side) along range and Doppler."""

    guard_range: int
    guard_doppler: int
    train_range: int
    train_doppler: int

    def __post_init__(self) -> None:
        values = (self.guard_range, self.guard_doppler, self.train_range, self.train_doppler)
        if any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0 for v in values):
            raise ValueError(f"guard and train must be pairs of non-negative integers, got {values}")
        if self.n_train < 2:
            raise ValueError("the training region is empty: increase train=(tr, td)")

    @property
    def half_range(self) -> int:
        return int(self.guard_range + self.train_range)

    @property
    def half_doppler(self) -> int:
        return int(self.guard_doppler + self.train_doppler)

    @property
    def n_train(self) -> int:
        """Number of training cells ``N``."""
        outer = (2 * self.half_range + 1) * (2 * self.half_doppler + 1)
        inner = (2 * self.guard_range + 1) * (2 * self.guard_doppler + 1)
        return int(outer - inner)

    def offsets(self) -> np.ndarray:
        """``[N, 2]`` (range, Doppler) offsets of the training cells."""
        dr, dd = np.meshgrid(
            np.arange(-self.half_range, self.half_range + 1),
            np.arange(-self.half_doppler, self.half_doppler + 1),
            indexing="ij",
        )
        ring = (np.abs(dr) > self.guard_range) | (np.abs(dd) > self.guard_doppler)
        return np.stack([dr[ring], dd[ring]], axis=1)


class CfarResult:
    """Output of :func:`cfar_2d`; all arrays ``[..., R, D]`` like the input map.

    Attributes
    ----------
    mask : numpy.ndarray
        bool, ``power > threshold``.
    threshold : numpy.ndarray
        float64 detection threshold, power units. For OS it is computed on first
        access (a selection per cell, ~10x the cost of the detection itself).
    noise_power : numpy.ndarray
        float64 estimate of the mean noise power per cell: the training mean
        (CA), the selected half mean (SO/GO), or the ordered statistic divided by
        its expectation factor ``sum_{i<k} 1/(N-i)`` (OS). Computed on first
        access for OS, like ``threshold``; see :meth:`noise_power_at` for a few cells.
    alpha : float
        Threshold factor on the CFAR statistic (mean or ordered value).
    n_train : int
        Training cells per window ``N``.
    method : str
    """

    def __init__(
        self,
        mask: np.ndarray,
        threshold: np.ndarray | None,
        noise_power: np.ndarray | None,
        alpha: float,
        n_train: int,
        method: str,
        *,
        lazy_statistic: _LazyOrderedStatistic | None = None,
    ) -> None:
        if (threshold is None or noise_power is None) and lazy_statistic is None:
            raise ValueError("pass threshold and noise_power maps (or a lazy statistic)")
        for name, value in (("threshold", threshold), ("noise_power", noise_power)):
            if value is not None and np.shape(value) != np.shape(mask):
                raise ValueError(f"mask {np.shape(mask)} and {name} {np.shape(value)} must have one shape")
        self.mask = mask
        self.alpha = alpha
        self.n_train = n_train
        self.method = method
        self._threshold = threshold
        self._noise_power = noise_power
        self._lazy = lazy_statistic

    @property
    def threshold(self) -> np.ndarray:
        if self._threshold is None:
            self._threshold = self._lazy.threshold(self.alpha)
        return self._threshold

    @property
    def noise_power(self) -> np.ndarray:
        if self._noise_power is None:
            self._noise_power = self._lazy.noise_power()
        return self._noise_power

    def noise_power_at(self, *index: np.ndarray) -> np.ndarray:
        """``noise_power[index]`` for integer index arrays (e.g. ``numpy.nonzero(mask)``).

        For OS without the full map computed, selects the ordered statistic at
        these cells only.
        """
        if self._noise_power is None:
            return self._lazy.noise_power_at(index)
        return self._noise_power[index]

    def __repr__(self) -> str:
        return (
            f"CfarResult(method={self.method!r}, shape={self.mask.shape}, detections={int(self.mask.sum())}, "
            f"alpha={self.alpha:.6g}, n_train={self.n_train})"
        )


# --- threshold factors from Pfa -------------------------------------------------


def ca_alpha(n_train: int, pfa: float) -> float:
    """CA-CFAR factor on the training mean: ``N * (pfa**(-1/N) - 1)``."""
    return float(n_train * (pfa ** (-1.0 / n_train) - 1.0))


def so_pfa(t: float, n_half: int) -> float:
    """False-alarm probability of SO-CFAR with factor ``t`` on the smaller half *sum* of ``n_half`` cells."""
    return float(2.0 * sum(comb(n_half - 1 + k, k) * (2.0 + t) ** (-(n_half + k)) for k in range(n_half)))


def go_pfa(t: float, n_half: int) -> float:
    """False-alarm probability of GO-CFAR with factor ``t`` on the larger half *sum* of ``n_half`` cells."""
    return float(2.0 * (1.0 + t) ** (-n_half) - so_pfa(t, n_half))


def os_pfa(alpha: float, n_train: int, rank: int) -> float:
    """False-alarm probability of OS-CFAR with factor ``alpha`` on the ``rank``-th smallest of ``n_train`` cells."""
    i = np.arange(rank)
    return float(np.exp(np.sum(np.log(n_train - i) - np.log(n_train - i + alpha))))


def _solve_decreasing(pfa_of: Any, pfa: float) -> float:
    target = log(pfa)
    hi = 1.0
    while log(max(pfa_of(hi), 1e-300)) > target:
        hi *= 2.0
        if hi > 1e12:
            raise ValueError(f"pfa={pfa} is not reachable with this window")
    return float(scipy.optimize.brentq(lambda a: log(max(pfa_of(a), 1e-300)) - target, 0.0, hi, xtol=1e-12, rtol=1e-12))


@lru_cache(maxsize=256)
def cfar_alpha(method: str, n_train: int, pfa: float, os_rank: int | None = None) -> float:
    """Threshold factor on the method's noise statistic (a *mean*, or the ordered value for OS)."""
    if method == "ca":
        return ca_alpha(n_train, pfa)
    if method in ("so", "go"):
        n_half = n_train // 2
        pfa_fn = so_pfa if method == "so" else go_pfa
        return _solve_decreasing(lambda t: pfa_fn(t, n_half), pfa) * n_half
    if method == "os":
        rank = default_os_rank(n_train) if os_rank is None else os_rank
        return _solve_decreasing(lambda a: os_pfa(a, n_train, rank), pfa)
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")


def default_os_rank(n_train: int) -> int:
    """``round(3N/4)``, the usual OS-CFAR rank (1-based)."""
    return max(1, min(n_train, int(round(0.75 * n_train))))


# --- box sums ---------------------------------------------------------------------


def _pad_indices(n: int, half: int, mode: str) -> np.ndarray:
    idx = np.arange(-half, n + half)
    if mode == "wrap":
        return idx % n
    # mirror without repeating the edge cell (numpy "reflect")
    idx = np.abs(idx)
    return np.where(idx > n - 1, 2 * (n - 1) - idx, idx)


@numba.njit(cache=True, nogil=True)
def _summed_area_kernel(power: np.ndarray, rows: np.ndarray, cols: np.ndarray, table: np.ndarray) -> None:
    n_maps = power.shape[0]
    for m in range(n_maps):
        table[m, 0, :] = 0.0
        for i in range(rows.size):
            running = 0.0
            table[m, i + 1, 0] = 0.0
            for j in range(cols.size):
                running += power[m, rows[i], cols[j]]
                table[m, i + 1, j + 1] = table[m, i, j + 1] + running


def _summed_area(power: np.ndarray, window: CfarWindow, range_mode: str) -> np.ndarray:
    """Summed-area table of the padded maps, ``[M, R + 2hr + 1, D + 2hd + 1]`` float64, zero first row/column.

    Padding and both cumulative sums in one compiled pass (numpy's pad + two
    ``cumsum`` calls took 3x longer).
    """
    n_r, n_d = power.shape[-2:]
    rows = _pad_indices(n_r, window.half_range, range_mode)
    cols = _pad_indices(n_d, window.half_doppler, "wrap")
    maps = power.reshape(-1, n_r, n_d)
    table = np.empty((maps.shape[0], rows.size + 1, cols.size + 1), dtype=np.float64)
    _summed_area_kernel(maps, rows, cols, table)
    return table


@numba.njit(cache=True, nogil=True, inline="always")
def _box_at(table: np.ndarray, m: int, r: int, d: int, r0: int, r1: int, d0: int, d1: int) -> float:
    """Sum over rows ``r+r0..r+r1`` and columns ``d+d0..d+d1`` (padded coordinates, inclusive)."""
    return (
        table[m, r + r1 + 1, d + d1 + 1]
        - table[m, r + r0, d + d1 + 1]
        - table[m, r + r1 + 1, d + d0]
        + table[m, r + r0, d + d0]
    )


@numba.njit(cache=True)  # serial: on busy shared cores numba's thread pool ran up to 10x slower
def _box_cfar_kernel(
    table: np.ndarray,
    power: np.ndarray,
    gr: int,
    gd: int,
    hr: int,
    hd: int,
    method: int,
    alpha: float,
    stat: np.ndarray,
    threshold: np.ndarray,
) -> None:
    """CA (0) / SO (1) / GO (2) statistic and threshold from a summed-area table.

    One fused pass: the same corner arithmetic in numpy makes ~15 map-sized
    temporaries and was 4x slower.
    """
    n_r, n_d = power.shape[1:]
    n_maps = power.shape[0]
    n_total = (2 * hr + 1) * (2 * hd + 1) - (2 * gr + 1) * (2 * gd + 1)
    n_half = n_total // 2
    for row in numba.prange(n_maps * n_r):
        m = row // n_r
        r = row % n_r
        for d in range(n_d):
            # padded coordinates of the CUT are (r + hr, d + hd)
            rr = r + hr
            dd = d + hd
            total = _box_at(table, m, rr, dd, -hr, hr, -hd, hd) - _box_at(table, m, rr, dd, -gr, gr, -gd, gd)
            if method == 0:
                value = total / n_total
            else:
                near = _box_at(table, m, rr, dd, -hr, -1, -hd, hd) + _box_at(table, m, rr, dd, 0, 0, -hd, -gd - 1)
                if gr > 0:
                    near -= _box_at(table, m, rr, dd, -gr, -1, -gd, gd)
                far = total - near
                if method == 1:
                    value = min(near, far) / n_half
                else:
                    value = max(near, far) / n_half
            # Round-off of the summed-area differences can leave tiny negatives.
            value = max(value, 0.0)
            stat[m, r, d] = value
            threshold[m, r, d] = alpha * value


# --- ordered statistic ------------------------------------------------------------


@numba.njit(cache=True, nogil=True)
def _median3(a: np.ndarray, n: int) -> float:
    x0, x1, x2 = a[0], a[n >> 1], a[n - 1]
    return max(min(x0, x1), min(max(x0, x1), x2))


@numba.njit(cache=True, nogil=True)
def _kth_smallest(a: np.ndarray, b: np.ndarray, n: int, k: int) -> float:
    """k-th smallest (0-based) of ``a[:n]``; ``a`` is overwritten, ``b`` is scratch.

    Quickselect with branch-free three-way partitions: on random data the
    classic Hoare loop mispredicts about every other comparison, which made it
    3x slower here.
    """
    pivot = _median3(a, n)
    while True:
        n_less = 0
        for t in range(n):
            v = a[t]
            b[n_less] = v
            n_less += v < pivot
        n_greater = 0
        for t in range(n):
            v = a[t]
            a[n_greater] = v
            n_greater += v > pivot
        if k < n_less:
            n = n_less
            a[:n] = b[:n]
        elif k >= n - n_greater:
            k -= n - n_greater
            n = n_greater
        else:
            return pivot
        if n == 1:
            return a[0]
        pivot = _median3(a, n)


@numba.njit(cache=True, nogil=True)
def _os_detect_kernel(
    padded: np.ndarray, alpha: float, gr: int, gd: int, hr: int, hd: int, k: int, mask: np.ndarray
) -> None:
    """OS-CFAR decision ``x_cut > alpha * X_(k)`` for every cell, without selecting ``X_(k)``.

    Exactness, in floating point: let ``y_i = fl(alpha * x_i)`` and the threshold
    ``t = fl(alpha * X_(k))`` (float64 products, as :attr:`CfarResult.threshold`
    computes them). Rounding is monotone and ``alpha > 0``, so ``x_i <= x_j``
    implies ``y_i <= y_j``: the order of the ``x`` is an order of the ``y`` and
    ``t = Y_(k)``, the k-th smallest ``y``. Then ``x_cut > Y_(k)`` iff
    ``#{i : y_i < x_cut} >= k``: if ``Y_(k) < x_cut``, so are
    ``Y_(1) <= ... <= Y_(k)``; if ``k`` of the ``y_i`` are below ``x_cut``, the
    k-th smallest is at most the largest of them. Tied values need no special
    case: each is counted by the same strict comparison as the definition's
    strict ``>``. (NaN compares false, so it counts as ``+inf`` would.)

    The count runs, for one CUT row at a time, over whole ring rows with the CUT
    index innermost: contiguous compare-and-add that LLVM vectorises (N compares
    per cell instead of a selection's several partition passes). No ``fastmath``:
    it would let LLVM assume no inf/NaN and reassociate ``alpha * x``, and the
    integer count vectorises without it.

    Serial on purpose, by measurement (512 x 256 map, 248 training cells, 2-core
    machine): best of 60 runs 5.9 ms serial against 2.5 ms with ``parallel=True``
    on 2 threads (the idle case), medians 17-19 ms for both with other work
    running. Two threads save ~3 ms of a 100 ms budget, but numba's pool is GNU
    OpenMP here, which is not fork-safe, and maps are usually processed in forked
    data-loader workers, where extra threads per worker also oversubscribe cores.
    """
    n_maps, n_r, n_d = mask.shape
    width = 2 * hd + 1
    td = hd - gd
    counts = np.empty(n_d, dtype=np.int64)
    for m in range(n_maps):
        for r in range(n_r):
            counts[:] = 0
            cut = padded[m, r + hr, hd : hd + n_d]
            for dr in range(-hr, hr + 1):
                line = padded[m, r + hr + dr]
                for j in range(width):
                    if abs(dr) <= gr and td <= j < width - td:
                        continue  # guard box
                    for d in range(n_d):
                        counts[d] += alpha * line[d + j] < cut[d]
            for d in range(n_d):
                mask[m, r, d] = counts[d] >= k


@numba.njit(cache=True, nogil=True)
def _os_kernel(padded: np.ndarray, offsets: np.ndarray, half_r: int, half_d: int, k: int, out: np.ndarray) -> None:
    """The k-th smallest (0-based) training cell of every cell (full statistic map)."""
    n_maps, n_r, n_d = out.shape
    n = offsets.shape[0]
    a = np.empty(n, dtype=np.float64)
    b = np.empty(n, dtype=np.float64)
    for m in range(n_maps):
        for r in range(n_r):
            for d in range(n_d):
                for t in range(n):
                    a[t] = padded[m, r + half_r + offsets[t, 0], d + half_d + offsets[t, 1]]
                out[m, r, d] = _kth_smallest(a, b, n, k)


@numba.njit(cache=True, nogil=True)
def _os_at_kernel(
    padded: np.ndarray, offsets: np.ndarray, half_r: int, half_d: int, k: int, cells: np.ndarray, out: np.ndarray
) -> None:
    """The k-th smallest training cell at ``cells`` (``[C, 3]`` map, range, Doppler indices)."""
    n = offsets.shape[0]
    a = np.empty(n, dtype=np.float64)
    b = np.empty(n, dtype=np.float64)
    for c in range(cells.shape[0]):
        m, r, d = cells[c, 0], cells[c, 1], cells[c, 2]
        for t in range(n):
            a[t] = padded[m, r + half_r + offsets[t, 0], d + half_d + offsets[t, 1]]
        out[c] = _kth_smallest(a, b, n, k)


def _padded_maps(power: np.ndarray, window: CfarWindow, range_mode: str) -> np.ndarray:
    """``[M, R + 2hr, D + 2hd]`` float64 maps with the edge handling applied."""
    n_r, n_d = power.shape[-2:]
    rows = _pad_indices(n_r, window.half_range, range_mode)
    cols = _pad_indices(n_d, window.half_doppler, "wrap")
    maps = power.reshape(-1, n_r, n_d)
    return np.ascontiguousarray(np.take(np.take(maps, rows, axis=-2), cols, axis=-1), dtype=np.float64)


class _LazyOrderedStatistic:
    """OS statistic maps computed on demand, in full or at a few cells.

    ``blank_rows`` range rows at each end are untested (``edge="valid-range"``):
    threshold +inf, noise NaN there.
    """

    def __init__(self, padded: np.ndarray, window: CfarWindow, rank: int, shape: tuple[int, ...], blank_rows: int) -> None:
        self.padded = padded
        self.window = window
        self.rank = rank
        self.shape = shape
        self.blank_rows = blank_rows
        self.scale = float(np.sum(1.0 / (window.n_train - np.arange(rank))))
        self._statistic: np.ndarray | None = None

    def statistic(self) -> np.ndarray:
        if self._statistic is None:
            n_r, n_d = self.shape[-2:]
            out = np.empty((self.padded.shape[0], n_r, n_d), dtype=np.float64)
            offsets = self.window.offsets().astype(np.int64)
            _os_kernel(self.padded, offsets, self.window.half_range, self.window.half_doppler, self.rank - 1, out)
            self._statistic = out.reshape(self.shape)
        return self._statistic

    def _blank(self, values: np.ndarray, fill: float) -> np.ndarray:
        if self.blank_rows:
            n_r = self.shape[-2]
            values[..., : self.blank_rows, :] = fill
            values[..., n_r - self.blank_rows :, :] = fill
        return values

    def threshold(self, alpha: float) -> np.ndarray:
        return self._blank(alpha * self.statistic(), np.inf)

    def noise_power(self) -> np.ndarray:
        return self._blank(self.statistic() / self.scale, np.nan)

    def noise_power_at(self, index: tuple[np.ndarray, ...]) -> np.ndarray:
        n_r, n_d = self.shape[-2:]
        if len(index) != len(self.shape):
            raise ValueError(f"noise_power_at needs {len(self.shape)} index arrays, got {len(index)}")
        flat = np.ravel_multi_index(np.broadcast_arrays(*index), self.shape)
        m, cell = np.divmod(flat.ravel(), n_r * n_d)
        r, d = np.divmod(cell, n_d)
        out = np.empty(flat.size, dtype=np.float64)
        offsets = self.window.offsets().astype(np.int64)
        cells = np.ascontiguousarray(np.stack([m, r, d], axis=1), dtype=np.int64)
        _os_at_kernel(self.padded, offsets, self.window.half_range, self.window.half_doppler, self.rank - 1, cells, out)
        out /= self.scale
        if self.blank_rows:
            out[(r < self.blank_rows) | (r >= n_r - self.blank_rows)] = np.nan
        return out.reshape(flat.shape)


def ordered_statistic_reference(power: np.ndarray, window: CfarWindow, rank: int, range_mode: str = "reflect") -> np.ndarray:
    """The same ordered statistic via ``scipy.ndimage.rank_filter`` (slower; kept as a cross-check)."""
    footprint = np.zeros((2 * window.half_range + 1, 2 * window.half_doppler + 1), dtype=bool)
    off = window.offsets()
    footprint[off[:, 0] + window.half_range, off[:, 1] + window.half_doppler] = True
    n_r, n_d = power.shape
    rows = _pad_indices(n_r, window.half_range, range_mode)
    cols = _pad_indices(n_d, window.half_doppler, "wrap")
    padded = np.take(np.take(power.astype(np.float64), rows, axis=0), cols, axis=1)
    filtered = scipy.ndimage.rank_filter(padded, rank - 1, footprint=footprint, mode="constant")
    return filtered[window.half_range : window.half_range + n_r, window.half_doppler : window.half_doppler + n_d]


# --- public entry point -------------------------------------------------------------


def _pair(value: Any, name: str) -> tuple[int, int]:
    try:
        a, b = value
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (range, doppler) of non-negative integers, got {value!r}") from None
    return a, b


def _window(guard: tuple[int, int], train: tuple[int, int]) -> CfarWindow:
    gr, gd = _pair(guard, "guard")
    tr, td = _pair(train, "train")
    return CfarWindow(gr, gd, tr, td)


def _misfit(window: CfarWindow, n_r: int, n_d: int, edge: str) -> str | None:
    if 2 * window.half_doppler + 1 > n_d:
        return f"the window spans {2 * window.half_doppler + 1} Doppler cells but the map has {n_d}"
    if (edge == "wrap" and 2 * window.half_range + 1 > n_r) or window.half_range > n_r - 1:
        return f"the window spans {2 * window.half_range + 1} range cells but the map has {n_r}"
    return None


def window_misfit(
    map_shape: tuple[int, ...],
    *,
    guard: tuple[int, int] = DEFAULT_GUARD,
    train: tuple[int, int] = DEFAULT_TRAIN,
    edge: str = "wrap-doppler",
) -> str | None:
    """Why :func:`cfar_2d`'s window does not fit maps of a shape, or None when it does.

    A caller checks with it first where a map too small for the window is an expected case (a
    recording of few range or Doppler cells) rather than a bug.

    Parameters
    ----------
    map_shape : tuple of int
        ``[..., R, D]`` the maps' shape.
    guard, train, edge
        As :func:`cfar_2d`.

    Returns
    -------
    str or None
        The message :func:`cfar_2d` raises its ValueError with, e.g. ``"the window spans 13 Doppler
        cells but the map has 8"``.
    """
    if edge not in EDGES:
        raise ValueError(f"edge must be one of {EDGES}, got {edge!r}")
    if len(map_shape) < 2:
        raise ValueError(f"map_shape must be [..., R, D], got {map_shape}")
    return _misfit(_window(guard, train), int(map_shape[-2]), int(map_shape[-1]), edge)


def cfar_2d(
    power: np.ndarray,
    *,
    method: str = "ca",
    guard: tuple[int, int] = DEFAULT_GUARD,
    train: tuple[int, int] = DEFAULT_TRAIN,
    pfa: float = 1e-4,
    os_rank: int | None = None,
    edge: str = "wrap-doppler",
) -> CfarResult:
    """2-D CFAR on square-law power maps.

    Parameters
    ----------
    power : numpy.ndarray
        ``[..., R, D]`` real non-negative power (range, Doppler).
    method : {"ca", "so", "go", "os"}
        Cell averaging, smallest-of, greatest-of or ordered statistic (module docstring).
    guard, train : (int, int)
        Guard and training cells on each side of the CUT, (range, Doppler).
    pfa : float
        Desired false-alarm probability per cell under i.i.d. exponential noise.
    os_rank : int, optional
        1-based rank ``k`` of the OS statistic, default ``round(3N/4)``.
    edge : {"wrap-doppler", "wrap", "valid-range"}
        Edge handling (module docstring).

    Returns
    -------
    CfarResult
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if edge not in EDGES:
        raise ValueError(f"edge must be one of {EDGES}, got {edge!r}")
    if not 0.0 < float(pfa) < 1.0:
        raise ValueError(f"pfa must lie in (0, 1), got {pfa!r}")
    window = _window(guard, train)
    gr, gd = window.guard_range, window.guard_doppler
    power = np.asarray(power)
    if power.ndim < 2 or np.iscomplexobj(power):
        raise ValueError(f"power must be a real [..., R, D] array, got {power.dtype} {power.shape}")
    n_r, n_d = power.shape[-2:]
    misfit = _misfit(window, n_r, n_d, edge)
    if misfit is not None:
        raise ValueError(misfit)
    n = window.n_train
    if method == "os":
        rank = default_os_rank(n) if os_rank is None else int(os_rank)
        if not 1 <= rank <= n:
            raise ValueError(f"os_rank must lie in [1, {n}], got {os_rank}")
    range_mode = "wrap" if edge == "wrap" else "reflect"
    alpha = cfar_alpha(method, n, float(pfa), os_rank)

    blank_rows = window.half_range if edge == "valid-range" else 0
    if method == "os":
        padded = _padded_maps(power, window, range_mode)
        mask = np.empty(padded.shape[:1] + power.shape[-2:], dtype=bool)
        _os_detect_kernel(padded, alpha, gr, gd, window.half_range, window.half_doppler, rank, mask)
        mask = mask.reshape(power.shape)
        if blank_rows:
            mask[..., :blank_rows, :] = False
            mask[..., n_r - blank_rows :, :] = False
        lazy = _LazyOrderedStatistic(padded, window, rank, power.shape, blank_rows)
        return CfarResult(mask, None, None, alpha, n, method, lazy_statistic=lazy)

    table = _summed_area(power, window, range_mode)
    maps = power.reshape(-1, n_r, n_d)
    stat = np.empty(maps.shape, dtype=np.float64)
    threshold = np.empty(maps.shape, dtype=np.float64)
    _box_cfar_kernel(
        table,
        maps,
        gr,
        gd,
        window.half_range,
        window.half_doppler,
        METHODS.index(method),
        alpha,
        stat,
        threshold,
    )
    noise = stat.reshape(power.shape)
    threshold = threshold.reshape(power.shape)
    if blank_rows:
        for rows in (slice(0, blank_rows), slice(n_r - blank_rows, n_r)):
            threshold[..., rows, :] = np.inf
            noise[..., rows, :] = np.nan
    mask = power > threshold
    return CfarResult(mask=mask, threshold=threshold, noise_power=noise, alpha=alpha, n_train=n, method=method)


# --- detections ------------------------------------------------------------------------


@dataclass
class CfarDetections:
    """Detections in one range-Doppler map; every field is ``[M]``.

    Attributes
    ----------
    range_bin, doppler_bin : numpy.ndarray
        int64 cell indices (Doppler bin ``D // 2`` is zero velocity).
    range_m : numpy.ndarray
        float64 range of the cell, m.
    velocity_mps : numpy.ndarray
        float64 radial velocity of the cell, m/s (> 0: receding).
    snr_db : numpy.ndarray
        float64 ``10 log10(power / noise_power)`` of the cell.
    power : numpy.ndarray
        float64 cell power.
    """

    range_bin: np.ndarray
    doppler_bin: np.ndarray
    range_m: np.ndarray
    velocity_mps: np.ndarray
    snr_db: np.ndarray
    power: np.ndarray

    def __post_init__(self) -> None:
        shapes = {name: np.shape(getattr(self, name)) for name in self.__dataclass_fields__}
        if len(set(shapes.values())) != 1 or len(next(iter(shapes.values()))) != 1:
            raise ValueError(f"CfarDetections fields must all be [M] arrays, got shapes {shapes}")

    def __len__(self) -> int:
        return int(self.range_bin.shape[0])


def local_maxima(power: np.ndarray) -> np.ndarray:
    """``[..., R, D]`` bool: cells not smaller than their 8 neighbours (Doppler wraps, range edges clamp)."""
    size = [1] * (power.ndim - 2) + [3, 3]
    modes = ["nearest"] * (power.ndim - 1) + ["wrap"]
    return power >= scipy.ndimage.maximum_filter(power, size=size, mode=modes)


def cell_spacing(params: Any, n_range_bins: int, n_doppler_bins: int) -> tuple[float, float]:
    """(range_bin_m, doppler_bin_mps) of a cube made from ``params`` by :func:`range_doppler`.

    Zero-padding to ``R > n_samples`` shrinks the range spacing by ``n_samples / R``.
    """
    if n_doppler_bins != params.n_chirps:
        raise ValueError(f"the map has {n_doppler_bins} Doppler bins but params.n_chirps is {params.n_chirps}")
    return params.range_bin_m * params.n_samples / max(params.n_samples, n_range_bins), params.doppler_bin_mps


def detect(
    cube_or_power: np.ndarray,
    params: Any = None,
    *,
    range_bin_m: float | None = None,
    doppler_bin_mps: float | None = None,
    local_max: bool = True,
    **cfar_kwargs: Any,
) -> CfarDetections:
    """CFAR detections with physical coordinates in one range-Doppler map.

    Parameters
    ----------
    cube_or_power : numpy.ndarray
        ``[R, D, A]`` complex cube (power summed over antennas, i.e. non-coherent
        integration) or ``[R, D]`` real power.
    params : FmcwParams, optional
        Gives the cell spacing (see :func:`cell_spacing`); or pass
        ``range_bin_m`` and ``doppler_bin_mps`` directly.
    local_max : bool
        Keep only detections that are local maxima of the power (one per peak
        instead of a blob of cells around each target).
    **cfar_kwargs
        Passed to :func:`cfar_2d` (``method``, ``guard``, ``train``, ``pfa``, ...).

    Returns
    -------
    CfarDetections
        Sorted by range bin, then Doppler bin.
    """
    x = np.asarray(cube_or_power)
    if np.iscomplexobj(x):
        if x.ndim != 3:
            raise ValueError(f"a complex cube must be [R, D, A], got shape {x.shape}")
        power = np.einsum("rda,rda->rd", x, x.conj()).real
    else:
        if x.ndim != 2:
            raise ValueError(f"a power map must be [R, D], got shape {x.shape}")
        power = x.astype(np.float64, copy=False)
    n_r, n_d = power.shape
    if params is not None:
        range_bin_m, doppler_bin_mps = cell_spacing(params, n_r, n_d)
    if range_bin_m is None or doppler_bin_mps is None:
        raise ValueError("pass params, or both range_bin_m and doppler_bin_mps")
    result = cfar_2d(power, **cfar_kwargs)
    mask = result.mask & local_maxima(power) if local_max else result.mask
    r_idx, d_idx = np.nonzero(mask)
    cell_power = power[r_idx, d_idx]
    with np.errstate(divide="ignore"):
        snr_db = 10.0 * np.log10(cell_power / result.noise_power_at(r_idx, d_idx))
    return CfarDetections(
        range_bin=r_idx.astype(np.int64),
        doppler_bin=d_idx.astype(np.int64),
        range_m=r_idx * float(range_bin_m),
        velocity_mps=(d_idx - n_d // 2) * float(doppler_bin_mps),
        snr_db=snr_db,
        power=cell_power,
    )
