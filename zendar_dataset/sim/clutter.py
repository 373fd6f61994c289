"""Ground clutter and the view dependence of diffuse surfaces.

A patch of asphalt or paving returns a weak, speckled echo.  Here the ground
from facade to facade (road, curbs, sidewalks) is cut into cells of
``spacing x spacing`` (jittered grid); each cell is one steady point scatterer
on the ground with a random amplitude ``a`` drawn from a Weibull law of shape
``k`` (``k = 2`` would be Rayleigh; ``k < 2`` gives the heavier tail measured
for ground clutter at low grazing angles), normalised to ``E[a²] = 1``, with a
uniform phase.  Its mean RCS follows the constant-gamma law of land clutter,
``sigma0 = gamma * sin(grazing)``: it falls steeply towards grazing
incidence, evaluated for each view by :func:`view_gains` (as is a building
wall's Lambertian ``cos²`` of the incidence angle).  Parameters and sources:
docs/simulator.md.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.stats

from zendar_dataset.sim.imperfections import Imperfections
from zendar_dataset.sim.rotate import dot
from zendar_dataset.sim.world import SURFACE_GROUND, SURFACE_WALL, Road, ScattererSet


def weibull_amplitude_law(shape_k: float) -> scipy.stats.rv_continuous:
    """The frozen Weibull law of a clutter cell's amplitude, scaled so that ``E[a²] = 1``."""
    scale = 1.0 / math.sqrt(math.gamma(1.0 + 2.0 / shape_k))
    return scipy.stats.weibull_min(shape_k, scale=scale)


def road_clutter(
    rng: np.random.Generator,
    road: Road,
    s_start_m: float,
    s_end_m: float,
    lateral_m: tuple[float, float],
    settings: Imperfections,
) -> ScattererSet:
    """Ground clutter cells (ENU, on the ground) over arc lengths ``[s_start_m, s_end_m]`` and lateral offsets ``lateral_m``.

    Each cell's ``rcs_m2`` is ``gamma * spacing² * a²``, its RCS at normal view; seen at a
    grazing angle ``psi`` it is that times ``sin(psi)`` (:func:`view_gains`). Returns an empty
    set when ``settings.road_clutter`` is off.
    """
    if not settings.road_clutter:
        return ScattererSet.empty()
    spacing = settings.clutter_spacing_m
    s = np.arange(s_start_m + spacing / 2, s_end_m, spacing)
    lateral = np.arange(lateral_m[0] + spacing / 2, lateral_m[1], spacing)
    s_grid, lateral_grid = (a.reshape(-1) for a in np.meshgrid(s, lateral, indexing="ij"))
    n = s_grid.shape[0]
    # Jitter within the cell: a regular lattice would add grating lobes no street has.
    s_grid = s_grid + rng.uniform(-spacing / 2, spacing / 2, n)
    lateral_grid = lateral_grid + rng.uniform(-spacing / 2, spacing / 2, n)
    position, _yaw = road.point(s_grid, lateral_grid)
    amplitude = weibull_amplitude_law(settings.clutter_weibull_shape).rvs(size=n, random_state=rng)
    rcs = 10.0 ** (settings.clutter_gamma_db / 10.0) * spacing**2 * amplitude**2
    return ScattererSet(position, rcs, np.zeros(n, bool), rng.uniform(0.0, 2.0 * np.pi, n),
                        surface=np.full(n, SURFACE_GROUND, np.int8))


def view_gains(scatterers: ScattererSet, radar_m: np.ndarray) -> np.ndarray:
    """Factor ``[S]`` on each scatterer's ``rcs_m2`` seen from ``radar_m`` ``[3]`` (same frame).

    Ground cells: ``sin`` of the grazing angle (zero from below the ground); wall cells: ``cos²`` of
    the angle between their outward normal and the direction to the radar (zero from behind);
    points: 1.
    """
    to_radar = np.asarray(radar_m, dtype=np.float64)[None, :] - scatterers.position_m
    distance = np.maximum(np.linalg.norm(to_radar, axis=-1), 1e-9)
    gains = np.ones(distance.shape[0])
    ground = scatterers.surface == SURFACE_GROUND
    gains[ground] = np.clip(to_radar[ground, 2] / distance[ground], 0.0, None)
    wall = scatterers.surface == SURFACE_WALL
    gains[wall] = np.clip(dot(scatterers.normal[wall], to_radar[wall]) / distance[wall], 0.0, None) ** 2
    return gains
