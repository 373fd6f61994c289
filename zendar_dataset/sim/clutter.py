"""Road clutter: the ground as distributed point scatterers with a heavy-tailed amplitude law.

A patch of asphalt returns a weak, speckled echo.  Here the ground between the
curbs is cut into cells of ``spacing x spacing`` (jittered grid); each cell is
one steady point scatterer on the ground with mean RCS ``sigma0 * spacing²``
and a random amplitude ``a`` drawn from a Weibull law of shape ``k``
(``k = 2`` would be Rayleigh; ``k < 2`` gives the heavier tail measured for
ground clutter at low grazing angles), normalised to ``E[a²] = 1``, with a
uniform phase.  Parameters and sources: docs/simulator.md.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.stats

from zendar_dataset.sim.imperfections import Imperfections
from zendar_dataset.sim.world import Road, ScattererSet


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
    """Clutter scatterers (ENU, on the ground) over arc lengths ``[s_start_m, s_end_m]`` and lateral offsets ``lateral_m``.

    Returns an empty set when ``settings.road_clutter`` is off.
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
    rcs = 10.0 ** (settings.clutter_sigma0_db / 10.0) * spacing**2 * amplitude**2
    return ScattererSet(position, rcs, np.zeros(n, bool), rng.uniform(0.0, 2.0 * np.pi, n))
