"""Optional CNN input channels beyond the paper's log-power maps: what the antennas' phases and the
ego's motion add (``zendar-bench --ablations``).

The paper's input keeps only each antenna's log power (:func:`zendar_baselines.cnn.maps.log_power_maps`),
so the phases, and with them the angle, are dropped. Two optional families of channels, per map:

- **phase differences**: ``cos`` and ``sin`` of the phase of ``x[a + 1] * conj(x[a])`` for each pair
  of neighbouring antennas (``2 (A - 1)`` channels). For a single plane wave from azimuth ``θ`` on
  antennas along the radar's y axis this phase is ``-2π (y[a + 1] - y[a]) sin θ / λ`` (the beat
  signal's phase falls with the shorter path to the nearer antenna): the angle, in a form without
  the ±π jump.
- **static Doppler**: the Doppler test's residual of every cell (1 channel): the cell's radial
  velocity minus the one a static point at the cell's azimuth would show given the radar's velocity
  over ground (:func:`zendar_dataset.detection.locate.locate_cells`, the test the detection chain
  applies to its points), wrapped onto the unambiguous span and divided by half of it (-1..1).
  Near 0 where a static scatterer explains the cell; a mover's residual is its own radial speed.

Channel layout of one map: the ``A`` log-power channels first (as the paper's input), then the phase
differences (``cos, sin`` of pair 0, then of pair 1, ...), then the static Doppler.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from zendar_dataset.detection.locate import locate_cells
from zendar_dataset.errors import ZendarError
from zendar_dataset.geometry.frames import EgoPoses
from zendar_dataset.radar import FmcwParams

from zendar_baselines.cnn.maps import log_power_maps

_CHUNK_FRAMES = 32


@dataclass(frozen=True)
class InputChannels:
    """Which optional channels a CNN's input holds beside each antenna's log power (module docstring).

    The default (neither) is the paper's input.
    """

    phase_differences: bool = False
    static_doppler: bool = False

    @property
    def is_paper_input(self) -> bool:
        """Log power alone, as in the paper."""
        return not (self.phase_differences or self.static_doppler)

    @property
    def name(self) -> str:
        """``power``, ``power+phase``, ``power+static-doppler`` or ``power+phase+static-doppler``."""
        return "+".join(["power", *(["phase"] if self.phase_differences else []),
                         *(["static-doppler"] if self.static_doppler else [])])

    def channels_per_map(self, n_antennas: int) -> int:
        """Channels of one map of a radar with ``n_antennas`` receivers."""
        return n_antennas + (2 * (n_antennas - 1) if self.phase_differences else 0) + (1 if self.static_doppler else 0)

    def to_json(self) -> dict[str, bool] | None:
        """What a checkpoint's architecture records: None for the paper's input (older checkpoints hold none)."""
        if self.is_paper_input:
            return None
        return {"phase_differences": self.phase_differences, "static_doppler": self.static_doppler}

    @classmethod
    def from_json(cls, value: Any) -> InputChannels:
        """The channels a checkpoint's architecture records (``None`` or absent: the paper's input)."""
        if value is None:
            return cls()
        if not isinstance(value, dict) or set(value) != {"phase_differences", "static_doppler"} or not all(
                isinstance(flag, bool) for flag in value.values()):
            raise ZendarError(f"input channels: expected {{'phase_differences': bool, 'static_doppler': bool}}, found {value!r}")
        return cls(**value)


def phase_difference_maps(cubes: Any, *, out: np.ndarray | None = None) -> np.ndarray:
    """``cos`` and ``sin`` of the phase between neighbouring antennas, per cell.

    Parameters
    ----------
    cubes : array-like, complex, shape [N, R, D, A]
        Range-Doppler-antenna cubes; read :data:`_CHUNK_FRAMES` frames at a time.
    out : ndarray, float32, shape [N, 2 (A - 1), R, D], optional

    Returns
    -------
    ndarray, float32, shape [N, 2 (A - 1), R, D]
        Channel ``2 a`` is ``cos φ_a``, channel ``2 a + 1`` is ``sin φ_a``, with ``φ_a`` the phase of
        ``x[a + 1] conj(x[a])``; 1 and 0 where either antenna reads exactly zero.
    """
    n_frames, n_range, n_doppler, n_antennas = _cube_shape(cubes, "phase_difference_maps")
    if n_antennas < 2:
        raise ZendarError(f"phase_difference_maps: phase differences need at least 2 antennas, found {n_antennas}")
    expected = (n_frames, 2 * (n_antennas - 1), n_range, n_doppler)
    out = _output(out, expected, "phase_difference_maps")
    for start in range(0, n_frames, _CHUNK_FRAMES):
        chunk = np.asarray(cubes[start : start + _CHUNK_FRAMES]).astype(np.complex64, copy=False)
        product = chunk[..., 1:] * np.conj(chunk[..., :-1])  # [n, R, D, A - 1]
        magnitude = np.abs(product)
        unit = np.where(magnitude > 0, product / np.where(magnitude > 0, magnitude, 1), np.complex64(1))
        pairs = np.stack([unit.real, unit.imag], axis=-1)  # [n, R, D, A - 1, 2]
        pairs = pairs.reshape(*unit.shape[:3], -1)  # [n, R, D, 2 (A - 1)]: cos, sin of pair 0, then pair 1, ...
        out[start : start + len(chunk)] = np.moveaxis(pairs, 3, 1)
    return out


def static_doppler_maps(cubes: Any, timestamps_ns: np.ndarray, calibration: Any, poses: EgoPoses, *,
                        out: np.ndarray | None = None) -> np.ndarray:
    """The Doppler test's residual of every cell, over half the unambiguous velocity span.

    Parameters
    ----------
    cubes : array-like, complex, shape [N, R, D, A]
        One radar's cubes (Doppler bin ``D // 2`` is zero radial velocity).
    timestamps_ns : ndarray, int64, shape [N]
        The cubes' times.
    calibration
        The radar's calibration record (waveform, antennas and mount).
    poses : EgoPoses
        The scene's ego poses (the radar's velocity over ground, yaw rate included).
    out : ndarray, float32, shape [N, 1, R, D], optional

    Returns
    -------
    ndarray, float32, shape [N, 1, R, D]
        ``residual_mps / (span_mps / 2)`` in ``[-1, 1)``, ``span_mps = D * doppler_bin_mps``: the cell's
        radial velocity minus a static point's at the cell's azimuth (Bartlett DOA of its antenna vector).
    """
    n_frames, n_range, n_doppler, _ = _cube_shape(cubes, "static_doppler_maps")
    timestamps_ns = np.asarray(timestamps_ns)
    if timestamps_ns.shape != (n_frames,):
        raise ZendarError(f"static_doppler_maps: expected {n_frames} timestamps, found shape {timestamps_ns.shape}")
    out = _output(out, (n_frames, 1, n_range, n_doppler), "static_doppler_maps")
    params = FmcwParams.from_calibration(calibration, n_samples=n_range, n_chirps=n_doppler)
    half_span_mps = n_doppler * float(params.doppler_bin_mps) / 2
    range_bin, doppler_bin = (index.ravel() for index in np.indices((n_range, n_doppler)))
    for k in range(n_frames):
        _, residual_mps = locate_cells(np.asarray(cubes[k]), range_bin, doppler_bin, int(timestamps_ns[k]), calibration, poses)
        out[k, 0] = (residual_mps / half_span_mps).reshape(n_range, n_doppler)
    return out


def input_maps(cubes: Any, channels: InputChannels, *, timestamps_ns: np.ndarray | None = None,
               calibration: Any = None, poses: EgoPoses | None = None, out: np.ndarray | None = None) -> np.ndarray:
    """One radar's CNN input maps: log power per antenna, then the optional channels (module docstring).

    Parameters
    ----------
    cubes : array-like, complex, shape [N, R, D, A]
    channels : InputChannels
    timestamps_ns, calibration, poses
        Needed for the static Doppler channel only (:func:`static_doppler_maps`).
    out : ndarray, float32, shape [N, C, R, D], optional
        ``C = channels.channels_per_map(A)`` (e.g. a memory map).

    Returns
    -------
    ndarray, float32, shape [N, C, R, D]
    """
    n_frames, n_range, n_doppler, n_antennas = _cube_shape(cubes, "input_maps")
    out = _output(out, (n_frames, channels.channels_per_map(n_antennas), n_range, n_doppler), "input_maps")
    log_power_maps(cubes, out=out[:, :n_antennas])
    first = n_antennas
    if channels.phase_differences:
        phase_difference_maps(cubes, out=out[:, first : first + 2 * (n_antennas - 1)])
        first += 2 * (n_antennas - 1)
    if channels.static_doppler:
        if timestamps_ns is None or calibration is None or poses is None:
            raise ZendarError("input_maps: the static Doppler channel needs the cubes' timestamps, the radar's calibration and the ego poses")
        static_doppler_maps(cubes, timestamps_ns, calibration, poses, out=out[:, first : first + 1])
    return out


def scene_input_maps(reader: Any, radar: str, channels: InputChannels, *, out: np.ndarray | None = None) -> np.ndarray:
    """:func:`input_maps` of one radar of an open scene (``reader``: a scene reader of the dataset)."""
    cubes = reader.array(f"radar/{radar}/cube")
    if channels.static_doppler:
        return input_maps(cubes, channels, timestamps_ns=reader.timestamps(f"radar/{radar}"),
                          calibration=reader.calibration.sensors[radar], poses=reader.ego_poses(), out=out)
    return input_maps(cubes, channels, out=out)


def _cube_shape(cubes: Any, what: str) -> tuple[int, int, int, int]:
    shape = tuple(getattr(cubes, "shape", ()))
    if len(shape) != 4:
        raise ZendarError(f"{what}: expected cubes of shape [N, R, D, A], found shape {shape}")
    if np.dtype(getattr(cubes, "dtype", np.float32)).kind != "c":
        raise ZendarError(f"{what}: expected complex cubes, found dtype {getattr(cubes, 'dtype', None)}")
    return shape  # type: ignore[return-value]


def _output(out: np.ndarray | None, expected: tuple[int, ...], what: str) -> np.ndarray:
    if out is None:
        return np.empty(expected, dtype=np.float32)
    if out.shape != expected or out.dtype != np.float32:
        raise ZendarError(f"{what}: out must be float32 of shape {expected}, found {out.dtype} {out.shape}")
    return out


__all__ = ["InputChannels", "input_maps", "phase_difference_maps", "scene_input_maps", "static_doppler_maps"]
