"""Imperfections of a real street and a real sensor: which are simulated, with what parameters.

Each effect is switched by a flag of :class:`Imperfections` (a field of every
simulation profile), so tests can isolate one.  The models live in small
modules: road clutter (:mod:`~zendar_dataset.sim.clutter`), mirror ghosts off
facades and guard rails (:mod:`~zendar_dataset.sim.multipath`), rotating wheels
(:mod:`~zendar_dataset.sim.wheels`); this module holds the two that act on the
radar itself or on a car's echo strength: per-antenna gain/phase calibration
error and the aspect dependence of a car's scatterers.  docs/simulator.md lists
every parameter and where its value comes from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from zendar_dataset.sim.rotate import dot


@dataclass(frozen=True)
class Imperfections:
    """Switches and parameters of the simulated imperfections.

    Attributes
    ----------
    road_clutter : bool
        Distributed scatterers on the ground from facade to facade: road, curbs, sidewalks
        (:mod:`zendar_dataset.sim.clutter`).
    clutter_gamma_db : float
        ``gamma`` of the ground's constant-gamma law, ``sigma0 = gamma * sin(grazing angle)``, dB m²/m².
    clutter_weibull_shape : float
        Shape ``k`` of the Weibull law of a clutter scatterer's amplitude (``k = 2``: Rayleigh).
    clutter_spacing_m : float
        Mean spacing of the clutter scatterers, metres (each stands for ``spacing²`` of ground).
    multipath : bool
        First-order (double-bounce) mirror ghosts of moving cars off building facades and guard rails.
    facade_reflection, rail_reflection : float
        Amplitude reflection coefficients ``|Γ|`` of a facade (concrete) and of a metal guard rail.
    car_aspect : bool
        A car scatterer's RCS depends on the angle between the line of sight and its surface normal.
    panel_half_width_deg : float
        One-sided 3 dB width of a flat panel's specular lobe, degrees.
    panel_floor_db : float
        A scatterer's RCS far from its lobe, relative to its peak, dB.
    wheel_micro_doppler : bool
        Rotating rim points on every wheel of a moving car (:mod:`zendar_dataset.sim.wheels`).
    wheel_radius_m, wheel_rcs_m2 : float
        Rolling radius of a wheel and RCS of each of its rim points.
    antenna_errors : bool
        A fixed gain/phase error per receive channel of each radar.
    antenna_phase_error_deg, antenna_gain_error_db : float
        Standard deviations of the per-channel phase (degrees) and gain (dB) errors.
    """

    road_clutter: bool = True
    clutter_gamma_db: float = -14.4
    clutter_weibull_shape: float = 1.5
    clutter_spacing_m: float = 1.0
    multipath: bool = True
    facade_reflection: float = 0.39
    rail_reflection: float = 1.0
    car_aspect: bool = True
    panel_half_width_deg: float = 10.0
    panel_floor_db: float = -15.0
    wheel_micro_doppler: bool = True
    wheel_radius_m: float = 0.31
    wheel_rcs_m2: float = 0.05
    antenna_errors: bool = True
    antenna_phase_error_deg: float = 5.0
    antenna_gain_error_db: float = 0.5

    @classmethod
    def none(cls) -> Imperfections:
        """Every effect switched off: the ideal street and sensor."""
        return cls(road_clutter=False, multipath=False, car_aspect=False, wheel_micro_doppler=False, antenna_errors=False)


def antenna_errors(sensor_index: int, n_rx: int, settings: Imperfections) -> np.ndarray:
    """Complex gain of each receive channel of one radar, ``[A]`` complex128 (all ones when off).

    A property of the radar unit, the same in every scene and dataset (the same two
    radars recorded them all).  Channel 0 is the reference (exactly 1): only
    differences between channels bias the direction of arrival.
    """
    if not settings.antenna_errors:
        return np.ones(n_rx, dtype=np.complex128)
    rng = np.random.default_rng([int(sensor_index), 0xA11])
    gain_db = rng.normal(0.0, settings.antenna_gain_error_db, n_rx)
    phase = np.radians(rng.normal(0.0, settings.antenna_phase_error_deg, n_rx))
    gain_db[0], phase[0] = 0.0, 0.0
    return 10.0 ** (gain_db / 20.0) * np.exp(1j * phase)


def surface_normals_body(position_body: np.ndarray, size_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward horizontal unit normals ``[S, 3]`` of a car's scatterers in its body frame, and corner flags ``[S]``.

    A scatterer on a side panel (at the half width, away from the ends) faces
    sideways, one on a bumper forward or back, one at a corner (both) diagonally;
    a point inside the footprint has no normal (zero) and radiates evenly.
    """
    p = np.asarray(position_body, dtype=np.float64)
    half_l, half_w = 0.5 * float(size_m[0]), 0.5 * float(size_m[1])
    along = np.where(np.abs(p[:, 0]) >= 0.95 * half_l, np.sign(p[:, 0]), 0.0)
    across = np.where(np.abs(p[:, 1]) >= 0.95 * half_w, np.sign(p[:, 1]), 0.0)
    normal = np.stack([along, across, np.zeros_like(along)], axis=1)
    norm = np.linalg.norm(normal, axis=1)
    normal = np.where(norm[:, None] > 0, normal / np.maximum(norm, 1e-12)[:, None], 0.0)
    return normal, (along != 0) & (across != 0)


def _lobes(cos_psi: np.ndarray, settings: Imperfections) -> tuple[np.ndarray, np.ndarray]:
    """Un-normalised panel and corner gains at ``cos(psi)``."""
    floor = 10.0 ** (settings.panel_floor_db / 10.0)
    q = math.log(0.5) / math.log(math.cos(math.radians(settings.panel_half_width_deg)))
    panel = floor + (1.0 - floor) * np.clip(cos_psi, 0.0, None) ** q
    psi = np.arccos(np.clip(cos_psi, -1.0, 1.0))
    corner = np.where(psi <= np.pi / 2, floor + (1.0 - floor) * np.cos(psi / 2) ** 2, floor)
    return panel, corner


@lru_cache(maxsize=8)
def _lobe_means(settings: Imperfections) -> tuple[float, float]:
    """Mean of each lobe over all horizontal aspects."""
    panel, wide = _lobes(np.cos(np.linspace(-np.pi, np.pi, 20001)), settings)
    return float(np.mean(panel)), float(np.mean(wide))


def aspect_gain(normal_world: np.ndarray, line_of_sight_world: np.ndarray, corner: np.ndarray,
                settings: Imperfections) -> np.ndarray:
    """RCS factor ``[S]`` of car scatterers seen along ``line_of_sight_world`` ``[S, 3]`` (scatterer to radar).

    Panels (bumpers, plates, side panels, wheel houses) reflect specularly:
    ``floor + (1 - floor) cos^q(psi)``, ``psi`` the horizontal angle between the
    normal and the line of sight, ``q`` such that the lobe is 3 dB down at
    ``panel_half_width_deg``; a face turned away leaves the floor. Corners
    (``corner`` ``[S]`` bool) reflect over the quarter they face,
    ``floor + (1 - floor) cos^2(psi / 2)`` for ``|psi| <= 90 deg``. Each law is
    divided by its mean over all horizontal aspects, so a scatterer keeps its RCS
    on average and only its aspect dependence is added.
    """
    if not settings.car_aspect:
        return np.ones(normal_world.shape[0])
    horizontal = np.array(line_of_sight_world, dtype=np.float64)
    horizontal[:, 2] = 0.0
    horizontal /= np.maximum(np.linalg.norm(horizontal, axis=-1, keepdims=True), 1e-12)
    panel, wide = _lobes(dot(normal_world, horizontal), settings)
    panel_mean, wide_mean = _lobe_means(settings)
    gain = np.where(corner, wide / wide_mean, panel / panel_mean)
    return np.where(np.linalg.norm(normal_world, axis=-1) > 0, gain, 1.0)
