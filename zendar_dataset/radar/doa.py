"""Direction of arrival (azimuth) for small receive arrays, batched over detections.

Snapshots are the complex antenna vectors of a detection: ``[N, A]`` (one
range-Doppler cell each) or ``[N, K, A]`` (``K`` snapshots each, e.g. the
detection's neighbouring cells, which carry the same steering vector). The
steering vector of azimuth ``theta`` (radar frame: x boresight, y left,
positive to the left) is ``a_a = exp(-j 2 pi u(theta) . p_a / lambda)``,
``u = (cos theta, sin theta, 0)`` (docs/architecture.md).

Covariance. ``R = mean_k x_k x_k^H`` over the snapshots and, on a uniform
linear array, over the ``A - L + 1`` subarrays of ``L`` elements (spatial
smoothing), then forward-backward averaged ``R <- (R + J conj(R) J) / 2`` on a
centro-symmetric array. A single snapshot gives a rank-one ``R``; Capon and
MUSIC need more, so by default they smooth with ``L = A - 1`` when ``K < A``
(with forward-backward averaging a single snapshot then yields rank up to
``2 (A - L + 1) = 4`` on 4 elements) and use the full array otherwise.

Spectra on the azimuth grid: Bartlett ``a^H R a / L``; Capon (MVDR)
``1 / a^H (R + delta I)^-1 a`` with diagonal loading ``delta =
loading * trace(R) / L``; MUSIC ``1 / |E_n^H a|^2`` with ``E_n`` the ``L -
n_sources`` eigenvectors of the smallest eigenvalues. Peaks are found on a
coarse grid, then each is refined on a fine grid one coarse step either side
and finally by a parabola through the three best fine samples. Every spectrum
is a real matrix product of ``[Re M, Im M]`` with features of the steering
vectors, which are computed once per grid, array and wavelength (the coarse
grid's and, around each coarse azimuth, the fine grid's): per call there is no
complex exponential left to take.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

METHODS = ("bartlett", "capon", "music")
_FINE_POINTS = 21


@dataclass
class DoaSpectrum:
    """Spatial spectra on an azimuth grid.

    Attributes
    ----------
    grid_rad : numpy.ndarray
        ``[G]`` azimuths, radians, radar frame.
    power : numpy.ndarray
        ``[N, G]`` float64 spectrum per detection (Bartlett/Capon: power;
        MUSIC: pseudo-spectrum).
    """

    grid_rad: np.ndarray
    power: np.ndarray

    def __post_init__(self) -> None:
        if self.power.ndim != 2 or self.power.shape[1] != self.grid_rad.shape[0]:
            raise ValueError(f"power must be [N, {self.grid_rad.shape[0]}], got {self.power.shape}")


def steering_vectors(azimuth_rad: np.ndarray, rx_positions_m: np.ndarray, wavelength_m: float) -> np.ndarray:
    """Steering vectors ``[..., A]`` complex128 for azimuths ``[...]`` (radians, zero elevation)."""
    az = np.asarray(azimuth_rad, dtype=np.float64)
    rx = np.asarray(rx_positions_m, dtype=np.float64)
    path = np.cos(az)[..., None] * rx[:, 0] + np.sin(az)[..., None] * rx[:, 1]
    return np.exp(-2j * np.pi * path / float(wavelength_m))


def is_centro_symmetric(rx_positions_m: np.ndarray) -> bool:
    """Whether ``[A, 3]`` antenna positions (metres) are symmetric about their centre, which
    forward-backward averaging needs (:func:`estimate_azimuth`)."""
    return _array_layout(np.ascontiguousarray(rx_positions_m, dtype=np.float64).tobytes())[1]


@functools.lru_cache(maxsize=16)
def _array_layout(rx_bytes: bytes) -> tuple[bool, bool]:
    """(uniform linear, centro-symmetric) of ``[A, 3]`` positions given as float64 bytes."""
    rx = np.frombuffer(rx_bytes, dtype=np.float64).reshape(-1, 3)
    tolerance = 1e-9 * max(1.0, float(np.abs(rx).max()))
    uniform = True
    if rx.shape[0] >= 2:
        step = np.diff(rx, axis=0)
        uniform = bool(np.allclose(step, step[0], atol=tolerance))
    pair_sum = rx + rx[::-1]
    return uniform, bool(np.allclose(pair_sum, pair_sum[0], atol=tolerance))


def spatial_covariance(snapshots: np.ndarray, *, subarray_size: int, forward_backward: bool) -> np.ndarray:
    """Sample covariance ``[N, L, L]`` with spatial smoothing over subarrays of ``L`` and optional forward-backward averaging.

    ``snapshots`` is ``[N, K, A]``; subarrays are contiguous runs of ``L`` elements
    (meaningful on a uniform linear array).
    """
    n, k, a = snapshots.shape
    sub = np.lib.stride_tricks.sliding_window_view(snapshots, subarray_size, axis=2)  # [N, K, P, L]
    sub = sub.reshape(n, -1, subarray_size)
    cov = np.einsum("nkl,nkm->nlm", sub, sub.conj()) / sub.shape[1]
    if forward_backward:
        cov = 0.5 * (cov + cov[:, ::-1, ::-1].conj())
    return cov


def _outer_features(steer: np.ndarray) -> np.ndarray:
    """Real features ``[..., 2 L^2]`` of steering vectors ``[..., L]`` for :func:`_quadratic_form`.

    ``Re(a^H M a) = sum_lm Re(M_lm) Re(conj(a_l) a_m) - Im(M_lm) Im(conj(a_l) a_m)``: the
    quadratic form becomes a dot product of ``[Re M, Im M]`` with these features.
    """
    outer = steer.conj()[..., :, None] * steer[..., None, :]
    flat = outer.reshape(*steer.shape[:-1], -1)
    return np.concatenate([flat.real, -flat.imag], axis=-1)


# Fine-search tables larger than this (float64 values) are not kept: the fine spectra are then
# computed per call from the detections' own fine azimuths, with the same numbers.
_MAX_FINE_TABLE_VALUES = 2_000_000


@dataclass(frozen=True)
class _SearchGrid:
    """The coarse grid's steering features and, per coarse azimuth, its fine azimuths and features.

    Computed once per (grid, array, wavelength): building them (complex exponentials
    and outer products) cost more than the searches themselves.
    """

    rx_m: np.ndarray  # [L, 3]
    wavelength_m: float
    coarse_features: np.ndarray  # [2 L^2, G]
    fine_az_rad: np.ndarray  # [G, F]: each coarse azimuth +- one coarse step
    fine_step_rad: float
    fine_features: np.ndarray | None  # [G, F, 2 L^2], None when too large to keep

    def fine_features_at(self, centre_index: np.ndarray) -> np.ndarray:
        """``[N, S*F, 2 L^2]`` features of the fine azimuths around coarse indices ``[N, S]``."""
        n = centre_index.shape[0]
        if self.fine_features is not None:
            return self.fine_features[centre_index].reshape(n, -1, self.coarse_features.shape[0])
        fine_az = self.fine_az_rad[centre_index].reshape(n, -1)
        return _outer_features(steering_vectors(fine_az, self.rx_m, self.wavelength_m))


@functools.lru_cache(maxsize=4)
def _search_grid(grid_bytes: bytes, rx_bytes: bytes, wavelength_m: float) -> _SearchGrid:
    grid = np.frombuffer(grid_bytes, dtype=np.float64)
    rx = np.frombuffer(rx_bytes, dtype=np.float64).reshape(-1, 3)
    step = float(np.median(np.diff(grid)))
    offsets = np.linspace(-step, step, _FINE_POINTS)
    fine_az = grid[:, None] + offsets
    coarse_features = _outer_features(steering_vectors(grid, rx, wavelength_m)).T.copy()
    fine_features = None
    if fine_az.size * coarse_features.shape[0] <= _MAX_FINE_TABLE_VALUES:
        fine_features = _outer_features(steering_vectors(fine_az, rx, wavelength_m))
        fine_features.setflags(write=False)
    for table in (coarse_features, fine_az):
        table.setflags(write=False)
    return _SearchGrid(rx, wavelength_m, coarse_features, fine_az, float(offsets[1] - offsets[0]), fine_features)


def _matrix_features(matrix: np.ndarray) -> np.ndarray:
    """``[N, 2 L^2]`` float64: ``[Re M, Im M]`` flattened, the other side of :func:`_outer_features`."""
    flat = matrix.reshape(matrix.shape[0], -1)
    return np.concatenate([flat.real, flat.imag], axis=1)


def _quadratic_form(matrix_features: np.ndarray, steer_features: np.ndarray) -> np.ndarray:
    """``Re(a^H M a)`` ``[N, G]`` from :func:`_matrix_features` ``[N, 2 L^2]`` and steering features.

    ``steer_features`` is ``[2 L^2, G]`` (a shared grid: one real matrix product, BLAS) or
    ``[N, G, 2 L^2]`` (a grid per detection). Batched 4 x 4 complex products in numpy cost
    ~3x more than these real products on the same numbers.
    """
    if steer_features.ndim == 2:
        return matrix_features @ steer_features
    return np.einsum("ngk,nk->ng", steer_features, matrix_features)


def _spectrum_matrix(cov: np.ndarray, method: str, n_sources: int, loading: float) -> np.ndarray:
    size = cov.shape[-1]
    if method == "bartlett":
        return cov / size
    if method == "capon":
        delta = loading * np.trace(cov, axis1=1, axis2=2).real / size + np.finfo(np.float64).tiny
        return np.linalg.inv(cov + delta[:, None, None] * np.eye(size))
    _, vectors = np.linalg.eigh(cov)  # ascending eigenvalues
    noise = vectors[:, :, : size - n_sources]
    return noise @ noise.conj().transpose(0, 2, 1)


def _spectrum(matrix_features: np.ndarray, steer_features: np.ndarray, method: str) -> np.ndarray:
    q = _quadratic_form(matrix_features, steer_features)
    if method == "bartlett":
        return q
    return 1.0 / np.maximum(q, 1e-300)


def _coarse_peaks(power: np.ndarray, n_sources: int) -> np.ndarray:
    """Indices ``[N, S]`` of the ``S`` highest local maxima (``-1`` where fewer exist)."""
    n, g = power.shape
    if n_sources == 1:
        return np.argmax(power, axis=1)[:, None]
    left = np.concatenate([np.full((n, 1), -np.inf), power[:, :-1]], axis=1)
    right = np.concatenate([power[:, 1:], np.full((n, 1), -np.inf)], axis=1)
    peak_power = np.where((power >= left) & (power > right), power, -np.inf)
    order = np.argsort(-peak_power, axis=1)[:, :n_sources]
    found = np.take_along_axis(peak_power, order, axis=1) > -np.inf
    return np.where(found, order, -1)


def estimate_azimuth(
    snapshots: np.ndarray,
    rx_positions_m: np.ndarray,
    wavelength_m: float,
    *,
    method: str = "bartlett",
    n_sources: int = 1,
    forward_backward: bool = True,
    subarray_size: int | None = None,
    grid_rad: np.ndarray | None = None,
    loading: float = 1e-3,
    return_spectrum: bool = False,
) -> Any:
    """Azimuth of the strongest source(s) per detection.

    Parameters
    ----------
    snapshots : numpy.ndarray
        ``[N, A]`` or ``[N, K, A]`` complex antenna vectors.
    rx_positions_m : numpy.ndarray
        ``[A, 3]`` receive-antenna positions, radar frame, metres.
    wavelength_m : float
    method : {"bartlett", "capon", "music"}
    n_sources : int
        Sources per detection (MUSIC's signal-subspace size; peaks returned).
    forward_backward : bool
        Forward-backward averaging; needs a centro-symmetric array (pass False otherwise).
    subarray_size : int, optional
        Spatial-smoothing subarray ``L`` (uniform linear arrays only); default in the module docstring.
    grid_rad : numpy.ndarray, optional
        Coarse search grid, default ``-90..90`` degrees in 1-degree steps.
    loading : float
        Capon diagonal loading relative to the mean eigenvalue.
    return_spectrum : bool
        Also return the :class:`DoaSpectrum` on the coarse grid.

    Returns
    -------
    numpy.ndarray or (numpy.ndarray, DoaSpectrum)
        ``[N]`` azimuth in radians (radar frame) for one source, else
        ``[N, n_sources]`` ordered by peak strength (NaN where fewer peaks).
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    x = np.asarray(snapshots)
    if x.ndim == 2:
        x = x[:, None, :]
    rx = np.asarray(rx_positions_m, dtype=np.float64)
    if x.ndim != 3 or rx.ndim != 2 or rx.shape != (x.shape[-1], 3):
        raise ValueError(
            f"snapshots must be [N, A] or [N, K, A] and rx_positions_m [A, 3]; got {np.shape(snapshots)} and {rx.shape}"
        )
    x = x.astype(np.complex128, copy=False)
    n_ant = rx.shape[0]
    n_snap = x.shape[1]
    uniform, centro_symmetric = _array_layout(np.ascontiguousarray(rx).tobytes())
    if subarray_size is None:
        small = method != "bartlett" and n_snap < n_ant and n_ant >= 3 and uniform
        subarray_size = n_ant - 1 if small else n_ant
    if not 1 <= subarray_size <= n_ant:
        raise ValueError(f"subarray_size must lie in [1, {n_ant}], got {subarray_size}")
    if subarray_size < n_ant and not uniform:
        raise ValueError("spatial smoothing (subarray_size < A) needs a uniform linear array")
    if forward_backward and not centro_symmetric:
        raise ValueError("forward-backward averaging needs a centro-symmetric array: pass forward_backward=False")
    if not 1 <= n_sources < max(subarray_size, 2):
        raise ValueError(f"n_sources must lie in [1, {subarray_size - 1}] for a {subarray_size}-element (sub)array")
    sub_rx = rx[:subarray_size]
    grid = np.arange(-90.0, 90.0 + 0.5, 1.0) * np.pi / 180.0 if grid_rad is None else np.asarray(grid_rad, np.float64)
    if grid.ndim != 1 or grid.size < 3:
        raise ValueError("grid_rad must be a 1-D array of at least 3 azimuths")

    if x.shape[0] == 0:
        empty = np.zeros((0,) if n_sources == 1 else (0, n_sources))
        return (empty, DoaSpectrum(grid_rad=grid, power=np.zeros((0, grid.size)))) if return_spectrum else empty
    cov = spatial_covariance(x, subarray_size=subarray_size, forward_backward=forward_backward)
    matrix = _matrix_features(_spectrum_matrix(cov, method, n_sources, loading))
    search = _search_grid(grid.tobytes(), np.ascontiguousarray(sub_rx).tobytes(), float(wavelength_m))
    coarse = _spectrum(matrix, search.coarse_features, method)
    peaks = _coarse_peaks(coarse, n_sources)  # [N, S]

    centre_index = np.clip(peaks, 0, grid.size - 1)
    n, s = peaks.shape
    fine = _spectrum(matrix, search.fine_features_at(centre_index), method).reshape(n, s, _FINE_POINTS)
    best = np.clip(np.argmax(fine, axis=2), 1, _FINE_POINTS - 2)
    rows = np.arange(n)[:, None]
    cols = np.arange(s)[None, :]
    y0, y1, y2 = (fine[rows, cols, best + o] for o in (-1, 0, 1))
    curvature = y0 - 2.0 * y1 + y2
    shift = np.where(curvature < 0, 0.5 * (y0 - y2) / np.where(curvature < 0, curvature, 1.0), 0.0)
    azimuth = search.fine_az_rad[centre_index, best] + np.clip(shift, -1.0, 1.0) * search.fine_step_rad
    azimuth = np.where(peaks >= 0, azimuth, np.nan)
    result = azimuth[:, 0] if n_sources == 1 else azimuth
    if return_spectrum:
        return result, DoaSpectrum(grid_rad=grid, power=coarse)
    return result


def _rotation_translation(ego_T_radar: Any) -> tuple[np.ndarray, np.ndarray]:
    if hasattr(ego_T_radar, "rotation") and hasattr(ego_T_radar, "translation"):
        rotation, translation = ego_T_radar.rotation, ego_T_radar.translation
    elif isinstance(ego_T_radar, tuple) and len(ego_T_radar) == 2:
        rotation, translation = ego_T_radar
    else:
        matrix = np.asarray(ego_T_radar, dtype=np.float64)
        if matrix.shape != (4, 4):
            raise ValueError("ego_T_radar must be (rotation [3, 3], translation [3]), a [4, 4] matrix or an SE3")
        rotation, translation = matrix[:3, :3], matrix[:3, 3]
    rotation = np.asarray(rotation, dtype=np.float64)
    translation = np.asarray(translation, dtype=np.float64)
    if rotation.shape != (3, 3) or translation.shape != (3,):
        raise ValueError(f"ego_T_radar rotation must be [3, 3] and translation [3], got {rotation.shape}, {translation.shape}")
    return rotation, translation


def detections_to_points(
    range_m: np.ndarray, azimuth_rad: np.ndarray, ego_T_radar: Any, *, elevation_rad: np.ndarray | float = 0.0
) -> np.ndarray:
    """Detections (range, azimuth) to points in the ego frame.

    Parameters
    ----------
    range_m, azimuth_rad : numpy.ndarray
        ``[N]`` range (m) and azimuth (rad, radar frame, positive to the left).
    ego_T_radar : (rotation, translation), [4, 4] array or object with ``rotation``/``translation``
        Radar pose in the ego frame, ``p_ego = R p_radar + t``.
    elevation_rad : float or numpy.ndarray
        Elevation (the array has no elevation resolution, so 0 by default: points
        lie in the radar's horizontal plane).

    Returns
    -------
    numpy.ndarray
        ``points_ego`` ``[N, 3]`` float64, metres.
    """
    rng = np.asarray(range_m, dtype=np.float64)
    az = np.asarray(azimuth_rad, dtype=np.float64)
    if rng.shape != az.shape or rng.ndim != 1:
        raise ValueError(f"range_m and azimuth_rad must both be [N], got {rng.shape} and {az.shape}")
    el = np.broadcast_to(np.asarray(elevation_rad, dtype=np.float64), rng.shape)
    rotation, translation = _rotation_translation(ego_T_radar)
    points_radar = np.stack([rng * np.cos(el) * np.cos(az), rng * np.cos(el) * np.sin(az), rng * np.sin(el)], axis=1)
    return points_radar @ rotation.T + translation
