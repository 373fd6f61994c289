"""SAR formed from simulated range profiles: focus and resolution of a static point, smear of a moving one."""

import numpy as np
import pytest

from tests.sar.point_target import half_power_width
from zendar_dataset.radar.fmcw import SPEED_OF_LIGHT_MPS
from zendar_dataset.sar.aperture import cross_range_resolution_m
from zendar_dataset.sar.grid import ImageGrid
from zendar_dataset.sim.ego import radar_params
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.radar_model import synthesize_range_profiles
from zendar_dataset.sim.sar_formation import AZIMUTH_WINDOW, form_image, profiles_for_backprojection

PARAMS = radar_params(get_profile("paper"))
EGO_SPEED = 10.0
# Side-looking radar: boresight (sensor x) along world +y, sensor y along world -x.
WORLD_R_SENSOR = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _image(target, target_velocity, aperture_m, pixel_m, shape):
    spacing = PARAMS.wavelength_m / 4
    x = np.arange(-aperture_m / 2, aperture_m / 2 + 1e-9, spacing)
    t = x / EGO_SPEED
    radar = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    world = target[None] + target_velocity[None] * t[:, None]
    local = ((world - radar) @ WORLD_R_SENSOR)[:, None, :]
    velocity = np.broadcast_to((target_velocity - [EGO_SPEED, 0, 0]) @ WORLD_R_SENSOR, local.shape)
    receiver = PARAMS.rx_positions_m[0]
    profiles = synthesize_range_profiles(PARAMS, local, velocity, np.ones((x.shape[0], 1)), receiver)
    centers = radar + WORLD_R_SENSOR @ (receiver / 2)
    grid = ImageGrid.axis_aligned(target, [1.0, 0, 0], [0, 1.0, 0], pixel_m, shape)
    return np.abs(form_image(PARAMS, profiles, centers, grid)), grid


def test_static_point_focuses_on_its_pixel_with_the_expected_azimuth_resolution():
    target = np.array([0.003, 10.0, 0.0])
    # Rows (along track) at 1 mm to measure the azimuth lobe; columns (range) at the paper's 4 cm.
    aperture, pixel = 0.2, 0.001
    image, grid = _image(target, np.zeros(3), aperture, (pixel, 0.04), (401, 21))
    i, j = np.unravel_index(np.argmax(image), image.shape)
    ti, tj, _ = grid.world_to_pixel(target)
    assert abs(i - ti) <= 1 and abs(j - tj) <= 1
    # The images are formed at the sweep's mid frequency, tapered by the Hann window (theta = 90 deg).
    _, _, frequency = profiles_for_backprojection(PARAMS, np.zeros((1, PARAMS.n_samples), np.complex64))
    spacing = PARAMS.wavelength_m / 4
    length = (np.arange(-aperture / 2, aperture / 2 + 1e-9, spacing).size - 1) * spacing
    expected = cross_range_resolution_m(10.0, SPEED_OF_LIGHT_MPS / frequency, length, np.pi / 2, AZIMUTH_WINDOW)
    assert AZIMUTH_WINDOW == "hann"
    assert half_power_width(image[:, j], pixel) == pytest.approx(expected, rel=0.01)


@pytest.mark.slow
def test_moving_target_is_displaced_and_defocused_more_as_it_moves_faster():
    target = np.array([0.0, 10.0, 0.0])
    direction = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    peaks, shifts = [], []
    for ratio in (0.0, 0.05, 0.15):
        image, grid = _image(target, ratio * EGO_SPEED * direction, 1.0, 0.02, (121, 31))
        i, j = np.unravel_index(np.argmax(image), image.shape)
        ti, tj, _ = grid.world_to_pixel(target)
        peaks.append(image.max())
        shifts.append(np.hypot(i - ti, j - tj) * 0.02)
    assert shifts[0] <= 0.02 * 1.5
    assert shifts[0] < shifts[1] < shifts[2]
    assert peaks[0] > peaks[1] > peaks[2]
    assert peaks[2] < 0.7 * peaks[0]
