"""Batched range-Doppler -> CFAR -> DOA chain in torch (CPU or CUDA).

The same mathematics as :mod:`~zendar_dataset.radar.range_doppler`,
:mod:`~zendar_dataset.radar.cfar` and :mod:`~zendar_dataset.radar.doa`, written
with torch operations so a batch of frames stays on the GPU: range-Doppler by
``torch.fft``, CA/SO/GO CFAR by box sums over a float64 summed-area table, OS
CFAR by ``unfold`` + ``kthvalue``, peak picking by a 3 x 3 max-pool, and DOA on
a fine azimuth grid (0.1 degree) refined by a parabola. Thresholds use the same
``cfar_alpha`` factors; edges follow ``edge="wrap-doppler"`` (Doppler circular,
range mirrored).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from zendar_dataset.radar.cfar import METHODS, CfarWindow, cfar_alpha, cell_spacing, default_os_rank
from zendar_dataset.radar.doa import METHODS as DOA_METHODS
from zendar_dataset.radar.doa import steering_vectors
from zendar_dataset.radar.fmcw import FmcwParams
from zendar_dataset.radar.range_doppler import WindowSpec, range_doppler


@dataclass
class BatchDetections:
    """Detections of a batch of frames; every field is a ``[M]`` tensor on the chain's device.

    Attributes
    ----------
    frame_index : int64, index of the frame in the batch.
    range_bin, doppler_bin : int64 cell indices (Doppler ``D // 2`` = zero velocity).
    range_m, velocity_mps, azimuth_rad, snr_db, power : float32 (metres, m/s (> 0 receding),
        radians in the radar frame, dB over the CFAR noise estimate, summed power over antennas).
    """

    frame_index: torch.Tensor
    range_bin: torch.Tensor
    doppler_bin: torch.Tensor
    range_m: torch.Tensor
    velocity_mps: torch.Tensor
    azimuth_rad: torch.Tensor
    snr_db: torch.Tensor
    power: torch.Tensor

    def __post_init__(self) -> None:
        shapes = {name: tuple(getattr(self, name).shape) for name in self.__dataclass_fields__}
        if len(set(shapes.values())) != 1 or len(next(iter(shapes.values()))) != 1:
            raise ValueError(f"BatchDetections fields must all be [M] tensors, got shapes {shapes}")

    def __len__(self) -> int:
        return int(self.frame_index.shape[0])


def _pad_map(power: torch.Tensor, half_r: int, half_d: int) -> torch.Tensor:
    """[B, R, D] -> [B, R + 2hr, D + 2hd]: Doppler circular, range mirrored (no edge repeat)."""
    x = power[:, None]
    if half_d:
        x = F.pad(x, (half_d, half_d, 0, 0), mode="circular")
    if half_r:
        x = F.pad(x, (0, 0, half_r, half_r), mode="reflect")
    return x[:, 0]


def cfar_torch(power: torch.Tensor, *, method: str = "ca", guard=(2, 2), train=(8, 4), pfa: float = 1e-4, os_rank: int | None = None):
    """CFAR of ``[B, R, D]`` power maps in torch; returns ``(mask, threshold, noise_power)`` like :func:`cfar_2d` (``edge="wrap-doppler"``)."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    gr, gd = guard
    tr, td = train
    window = CfarWindow(gr, gd, tr, td)
    hr, hd = window.half_range, window.half_doppler
    n_r, n_d = power.shape[-2:]
    if 2 * hd + 1 > n_d or hr > n_r - 1:
        raise ValueError(f"the CFAR window ({2 * hr + 1} x {2 * hd + 1}) does not fit the {n_r} x {n_d} map")
    n = window.n_train
    alpha = cfar_alpha(method, n, float(pfa), os_rank)
    padded = _pad_map(power, hr, hd)
    if method == "os":
        rank = default_os_rank(n) if os_rank is None else int(os_rank)
        patches = F.unfold(padded[:, None], (2 * hr + 1, 2 * hd + 1))  # [B, K, R*D]
        offsets = window.offsets()
        ring = torch.as_tensor((offsets[:, 0] + hr) * (2 * hd + 1) + offsets[:, 1] + hd, device=power.device)
        stat = patches[:, ring].kthvalue(rank, dim=1).values.reshape(power.shape)
        noise = stat / float(np.sum(1.0 / (n - np.arange(rank))))
    else:
        table = F.pad(padded.double().cumsum(-2).cumsum(-1), (1, 0, 1, 0))

        def box(r0: int, r1: int, d0: int, d1: int) -> torch.Tensor:
            a, b, c, e = hr + r0, hr + r1 + 1, hd + d0, hd + d1 + 1
            return (
                table[:, b : b + n_r, e : e + n_d]
                - table[:, a : a + n_r, e : e + n_d]
                - table[:, b : b + n_r, c : c + n_d]
                + table[:, a : a + n_r, c : c + n_d]
            )

        total = box(-hr, hr, -hd, hd) - box(-gr, gr, -gd, gd)
        if method == "ca":
            stat = total / n
        else:
            near = box(-hr, -1, -hd, hd) + box(0, 0, -hd, -gd - 1)
            if gr > 0:
                near = near - box(-gr, -1, -gd, gd)
            pick = torch.minimum if method == "so" else torch.maximum
            stat = pick(near, total - near) / (n // 2)
        stat = stat.clamp_min(0.0).to(power.dtype)
        noise = stat
    threshold = alpha * stat
    return power > threshold, threshold, noise


def _local_maxima(power: torch.Tensor) -> torch.Tensor:
    x = F.pad(power[:, None], (1, 1, 0, 0), mode="circular")
    x = F.pad(x, (0, 0, 1, 1), mode="replicate")
    return power >= F.max_pool2d(x, 3, stride=1)[:, 0]


class RadarChain:
    """Range-Doppler + CFAR + DOA for batches of frames of one radar.

    Parameters
    ----------
    params : FmcwParams
    device : str or torch.device
    range_window, doppler_window : window specs of :func:`range_doppler`
    cfar : dict
        Keyword arguments of :func:`cfar_torch` (``method``, ``guard``, ``train``, ``pfa``, ``os_rank``).
    doa_method : {"bartlett", "capon", "music"}
        Single-snapshot DOA per detection (forward-backward averaging, and for
        Capon/MUSIC spatial smoothing with ``L = A - 1``, as in :mod:`.doa`).
    local_max : bool
        Keep only CFAR cells that are 3 x 3 local maxima.
    grid_step_deg : float
        DOA grid step over ``[-90, 90]`` degrees before parabolic refinement.

    Examples
    --------
    >>> chain = RadarChain(params, device="cuda")            # doctest: +SKIP
    >>> dets = chain.from_raw(frames)  # frames [B, n_chirps, n_samples, A] complex64   # doctest: +SKIP
    """

    def __init__(
        self,
        params: FmcwParams,
        *,
        device: Any = "cpu",
        range_window: WindowSpec = "hann",
        doppler_window: WindowSpec = "hann",
        cfar: dict | None = None,
        doa_method: str = "bartlett",
        local_max: bool = True,
        grid_step_deg: float = 0.1,
    ) -> None:
        if doa_method not in DOA_METHODS:
            raise ValueError(f"doa_method must be one of {DOA_METHODS}, got {doa_method!r}")
        self.params = params
        self.device = torch.device(device)
        self.range_window = range_window
        self.doppler_window = doppler_window
        self.cfar = {"method": "ca", "guard": (2, 2), "train": (8, 4), "pfa": 1e-4, **(cfar or {})}
        self.doa_method = doa_method
        self.local_max = local_max
        rx = params.rx_positions_m
        a = params.n_antennas
        self.subarray_size = a - 1 if doa_method != "bartlett" and a >= 3 else a
        grid = np.deg2rad(np.arange(-90.0, 90.0 + 1e-9, grid_step_deg))
        self.grid_rad = torch.as_tensor(grid, dtype=torch.float32, device=self.device)
        steer = steering_vectors(grid, rx[: self.subarray_size], params.wavelength_m)  # [G, L]
        self.steer = torch.as_tensor(steer, dtype=torch.complex64, device=self.device)

    def from_raw(self, frames: Any) -> BatchDetections:
        """Detections from raw frames ``[B, n_chirps, n_samples, A]`` (numpy or torch)."""
        x = torch.as_tensor(frames, device=self.device)
        if x.ndim != 4 or tuple(x.shape[1:]) != (self.params.n_chirps, self.params.n_samples, self.params.n_antennas):
            p = self.params
            raise ValueError(f"frames must be [B, {p.n_chirps}, {p.n_samples}, {p.n_antennas}], got {tuple(x.shape)}")
        cube = range_doppler(x.to(torch.complex64), range_window=self.range_window, doppler_window=self.doppler_window)
        return self.from_cubes(cube)

    def from_cubes(self, cubes: Any) -> BatchDetections:
        """Detections from range-Doppler cubes ``[B, R, D, A]`` (numpy or torch)."""
        cube = torch.as_tensor(cubes, device=self.device)
        if cube.ndim != 4 or cube.shape[-1] != self.params.n_antennas:
            raise ValueError(f"cubes must be [B, R, D, {self.params.n_antennas}], got {tuple(cube.shape)}")
        cube = cube.to(torch.complex64)
        n_r, n_d = int(cube.shape[1]), int(cube.shape[2])
        range_bin_m, doppler_bin_mps = cell_spacing(self.params, n_r, n_d)
        power = (cube.real.square() + cube.imag.square()).sum(-1)  # [B, R, D]
        mask, _, noise = cfar_torch(power, **self.cfar)
        if self.local_max:
            mask &= _local_maxima(power)
        b, r, d = mask.nonzero(as_tuple=True)
        cell_power = power[b, r, d]
        snapshots = cube[b, r, d]  # [M, A]
        return BatchDetections(
            frame_index=b,
            range_bin=r,
            doppler_bin=d,
            range_m=r.to(torch.float32) * range_bin_m,
            velocity_mps=(d - n_d // 2).to(torch.float32) * doppler_bin_mps,
            azimuth_rad=self.azimuth(snapshots),
            snr_db=10.0 * torch.log10(cell_power / noise[b, r, d]),
            power=cell_power,
        )

    def azimuth(self, snapshots: torch.Tensor) -> torch.Tensor:
        """Azimuth ``[M]`` (radians) of single snapshots ``[M, A]`` on the grid, refined by a parabola."""
        if snapshots.shape[0] == 0:
            return torch.zeros(0, dtype=torch.float32, device=self.device)
        size = self.subarray_size
        sub = snapshots.unfold(-1, size, 1)  # [M, P, L]
        cov = torch.einsum("mpl,mpk->mlk", sub, sub.conj()) / sub.shape[1]
        cov = 0.5 * (cov + cov.flip(-1, -2).conj())
        if self.doa_method == "bartlett":
            matrix = cov
        elif self.doa_method == "capon":
            delta = 1e-3 * torch.diagonal(cov, dim1=-2, dim2=-1).real.sum(-1) / size + 1e-30
            matrix = torch.linalg.inv(cov + delta[:, None, None] * torch.eye(size, device=cov.device))
        else:
            _, vectors = torch.linalg.eigh(cov)
            noise = vectors[..., : size - 1]
            matrix = noise @ noise.conj().transpose(-1, -2)
        y = self.steer @ matrix.transpose(-1, -2)  # [M, G, L]
        q = (y * self.steer.conj()).sum(-1).real
        spectrum = q if self.doa_method == "bartlett" else 1.0 / q.clamp_min(1e-30)
        best = spectrum.argmax(-1).clamp(1, spectrum.shape[-1] - 2)
        y0, y1, y2 = (spectrum.gather(-1, (best + o)[:, None])[:, 0] for o in (-1, 0, 1))
        curvature = y0 - 2 * y1 + y2
        shift = torch.where(curvature < 0, 0.5 * (y0 - y2) / torch.where(curvature < 0, curvature, torch.ones_like(curvature)), 0.0)
        step = self.grid_rad[1] - self.grid_rad[0]
        return self.grid_rad[best] + shift.clamp(-1, 1) * step
