"""Range-Doppler cells that enter the detection chain: CFAR peaks of a cube, or the peaks of a CNN's probability map."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zendar_dataset.detection.params import ChainParams
from zendar_dataset.errors import ZendarError
from zendar_dataset.radar.cfar import cfar_2d, local_maxima


@dataclass(frozen=True)
class RadarCells:
    """Cells of one range-Doppler map; every field ``[N]``.

    Attributes
    ----------
    range_bin, doppler_bin : numpy.ndarray
        int64 indices (Doppler bin ``D // 2`` is zero velocity).
    score : numpy.ndarray
        float64 weight of each cell: linear SNR over the CFAR noise estimate (CFAR), or the
        predicted probability (a CNN's peaks).
    snr_db : numpy.ndarray or None
        float64 each cell's power over the CA-CFAR noise estimate, dB, where the cells' maker
        already has it (:func:`cfar_map`); None otherwise
        (:func:`zendar_dataset.detection.points.cell_snr_db` then computes it from the cube).
    """

    range_bin: np.ndarray
    doppler_bin: np.ndarray
    score: np.ndarray
    snr_db: np.ndarray | None = None

    def __post_init__(self) -> None:
        names = ("range_bin", "doppler_bin", "score") + (("snr_db",) if self.snr_db is not None else ())
        shapes = {name: np.shape(getattr(self, name)) for name in names}
        if len(set(shapes.values())) != 1 or len(shapes["score"]) != 1:
            raise ZendarError(f"RadarCells fields must all be [N] arrays, got shapes {shapes}")

    def __len__(self) -> int:
        return int(np.shape(self.score)[0])


def cube_power(cube: np.ndarray) -> np.ndarray:
    """``[R, D]`` float64 power summed over antennas (non-coherent) of a cube ``[R, D, A]``."""
    cube = np.asarray(cube)
    if cube.ndim != 3 or not np.iscomplexobj(cube):
        raise ZendarError(f"expected a complex range-Doppler cube [R, D, A], got {cube.dtype} of shape {cube.shape}")
    return np.einsum("rda,rda->rd", cube, cube.conj()).real


def cfar_map(power: np.ndarray, params: ChainParams | None = None) -> tuple[RadarCells, np.ndarray]:
    """CA-CFAR peaks of a power map and the noise estimate everywhere.

    Parameters
    ----------
    power : numpy.ndarray
        ``[R, D]`` float64 power (:func:`cube_power`).
    params : ChainParams, optional
        ``cfar_pfa``.

    Returns
    -------
    cells : RadarCells
        Cells over the threshold that are local maxima (one per peak), score = linear SNR.
    noise_power : numpy.ndarray
        ``[R, D]`` float64 CA noise estimate (training-cell mean), power units.
    """
    params = ChainParams() if params is None else params
    result = cfar_2d(power, method="ca", pfa=params.cfar_pfa)
    r_idx, d_idx = np.nonzero(result.mask & local_maxima(power))
    noise = result.noise_power
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = power[r_idx, d_idx] / noise[r_idx, d_idx]
        snr_db = 10.0 * np.log10(snr)
    return RadarCells(r_idx.astype(np.int64), d_idx.astype(np.int64), snr, snr_db), noise


def cfar_cells(cube: np.ndarray, params: ChainParams | None = None) -> RadarCells:
    """CA-CFAR peaks of a cube ``[R, D, A]`` (the classical detector's CFAR), score = linear SNR."""
    return cfar_map(cube_power(cube), params)[0]


def probability_peaks(probability: np.ndarray, floor: float) -> RadarCells:
    """The local peaks of a predicted moving-object probability map, one cell per peak.

    A cell is a peak when it is not smaller than its 8 neighbours, the Doppler axis wrapping round as
    for the CFAR peaks (:func:`zendar_dataset.radar.cfar.local_maxima`): a car's blob of cells gives
    one point, as CFAR gives one per peak, instead of a point (with its own DOA) per cell.

    Parameters
    ----------
    probability : numpy.ndarray
        ``[R, D]`` float per-cell probability of a moving object.
    floor : float
        Peaks below this probability are dropped (a low floor keeps the whole precision-recall curve;
        the score, not a cut, orders the detections).

    Returns
    -------
    RadarCells
        Score = the probability at the peak.
    """
    probability = np.asarray(probability, np.float64)
    if probability.ndim != 2:
        raise ZendarError(f"probability_peaks: probability must be [R, D], got shape {probability.shape}")
    r_idx, d_idx = np.nonzero((probability >= floor) & local_maxima(probability))
    return RadarCells(r_idx.astype(np.int64), d_idx.astype(np.int64), probability[r_idx, d_idx])
