"""The simulator's bytes depend on the seed only: not on BLAS/numba thread counts, the process or buffer alignment."""

import os
import subprocess
import sys

import numpy as np
import pytest

from zendar_dataset.radar.range_doppler import window_values
from zendar_dataset.sim.ego import radar_params
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.radar_model import RangeResponse, synthesize_cube
from zendar_dataset.sim.rotate import compose, dot, rotate, unrotate

# Prints hashes of what one fresh process simulates: a range-response table, and the first radar
# cube, SAR image and lidar sweep of a tiny scene.
_FINGERPRINT = """
import hashlib
import numpy as np
import pytest
from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.radar.range_doppler import window_values
from zendar_dataset.sim import ego as ego_model, scene
from zendar_dataset.sim.lidar import lidar_sweep
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.radar_model import RangeResponse

def digest(array):
    return hashlib.sha1(np.ascontiguousarray(array).tobytes()).hexdigest()

profile = get_profile("tiny")
truth = scene.build_scene(profile, 3, 1)
log = truth.tracklog_written
tracklog = PoseInterpolator(log.timestamp_ns, log.position_ecef, log.attitude_wxyz)
table = RangeResponse(window_values("hann", 256), 4)
cube = scene.simulate_cube(truth, profile, "front_right", 0.35, scene.stream_rng(3, 1, "front_right"))
image, grid, _ = scene.simulate_sar(truth, profile, "front_left", 0.45, scene.stream_rng(3, 1, "sar_front_left"), tracklog)
rotation, position = ego_model.sensor_poses_enu(truth.ego, ego_model.LIDAR, np.array(0.55))
points, _ = lidar_sweep(scene.stream_rng(3, 1, "lidar"), rotation, position, truth.world.boxes_at(0.55), 6.0)
print(digest(table.table), digest(table.table_rate), digest(cube), digest(image), digest(grid.origin), digest(points))
"""


def _fingerprint(threads: int) -> list[str]:
    env = dict(os.environ, OPENBLAS_NUM_THREADS=str(threads), OMP_NUM_THREADS=str(threads), NUMBA_NUM_THREADS=str(threads))
    done = subprocess.run([sys.executable, "-c", _FINGERPRINT], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout.split()


def test_fresh_processes_with_one_or_three_threads_simulate_identical_bytes():
    # Each process builds its own cached tables, as every `synth --jobs N` worker does.
    # (A BLAS product made the range-response table, hence the cubes, depend on the thread count.)
    one, three = _fingerprint(1), _fingerprint(3)
    assert len(one) == 6
    assert one == three


def test_range_response_table_matches_the_closed_form_of_the_periodic_hann_window():
    n = 64
    response = RangeResponse(window_values("hann", n), half_width_bins=4)
    nu = response.nu_min + np.arange(response.table.shape[0]) / response.oversample
    # Periodic Hann: its DFT has bins 0 and +-1 only, of magnitude N/2 and N/4.
    for bins, magnitude in ((0, n / 2), (1, n / 4), (-1, n / 4), (2, 0.0), (-3, 0.0), (5, 0.0)):
        value = response.table[np.argmin(np.abs(nu - bins))]
        assert abs(abs(value) - magnitude) < 1e-12 * n, (bins, value)
    # Between bins: the defining sum, evaluated directly in float64.
    k = np.arange(n) - (n - 1) / 2.0
    for index in (17, 200, 385):
        direct = np.sum(response.window * np.exp(2j * np.pi * k * nu[index] / n))
        assert abs(response.table[index] - direct) < 1e-12 * n


def _misaligned_copy(array: np.ndarray, offset_bytes: int) -> np.ndarray:
    """``array`` copied into a buffer that starts ``offset_bytes`` past a fresh allocation."""
    raw = np.zeros(array.nbytes + 128, dtype=np.uint8)
    start = (-raw.ctypes.data) % 64 + offset_bytes
    out = raw[start : start + array.nbytes].view(array.dtype).reshape(array.shape)
    out[...] = array
    return out


def test_cube_synthesis_and_rotations_do_not_depend_on_buffer_alignment():
    params = radar_params(get_profile("tiny"))
    rng = np.random.default_rng(5)
    n = 40
    start = np.stack([rng.uniform(3, 30, n), rng.uniform(-10, 10, n), rng.uniform(-1, 1, n)], axis=1)
    velocity = rng.uniform(-10, 10, (n, 3))
    t = np.arange(params.n_chirps) * params.chirp_interval_s
    positions = start[:, None, :] + velocity[:, None, :] * t[None, :, None]
    amplitudes = rng.normal(size=n) + 1j * rng.normal(size=n)
    reference = synthesize_cube(params, positions, amplitudes, half_width_bins=4)
    angles = rng.uniform(-np.pi, np.pi, params.n_chirps)
    rotation = np.zeros((params.n_chirps, 3, 3))
    rotation[:, 0, 0] = rotation[:, 1, 1] = np.cos(angles)
    rotation[:, 1, 0], rotation[:, 0, 1] = np.sin(angles), -np.sin(angles)
    rotation[:, 2, 2] = 1.0
    products = [unrotate(rotation, positions), rotate(rotation, positions), compose(rotation, rotation[::-1]), dot(positions, positions)]
    for offset in (0, 8, 16, 24, 40):
        shifted = [_misaligned_copy(positions, offset), _misaligned_copy(amplitudes, offset), _misaligned_copy(rotation, offset)]
        assert synthesize_cube(params, shifted[0], shifted[1], half_width_bins=4).tobytes() == reference.tobytes()
        again = [unrotate(shifted[2], shifted[0]), rotate(shifted[2], shifted[0]), compose(shifted[2], shifted[2][::-1]),
                 dot(shifted[0], shifted[0])]
        assert all(a.tobytes() == b.tobytes() for a, b in zip(again, products)), offset


def test_rotation_helpers_equal_the_matrix_products():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(7, 3, 3)), rng.normal(size=(3, 3))
    v = rng.normal(size=(5, 7, 3))
    np.testing.assert_allclose(rotate(a, v), np.einsum("mij,smj->smi", a, v), atol=1e-14)
    np.testing.assert_allclose(unrotate(a, v), np.einsum("mji,smj->smi", a, v), atol=1e-14)
    np.testing.assert_allclose(compose(a, b), a @ b, atol=1e-14)
    np.testing.assert_allclose(rotate(b, v[0, 0]), b @ v[0, 0], atol=1e-14)
    np.testing.assert_allclose(dot(v, v[0]), (v * v[0]).sum(-1), atol=1e-14)


_SYNTH_SAR_DIGEST = """
import hashlib, sys
import zarr
from zendar_dataset.sim.generate import synthesize_dataset
synthesize_dataset(sys.argv[1], "tiny", n_scenes=2, seed=0, progress=False, jobs=1)
for scene in ("scene-0000", "scene-0001"):
    group = zarr.open_group(f"{sys.argv[1]}/scenes/{scene}.zarr", mode="r")
    for sensor in sorted(group["sar"].group_keys()):
        print(hashlib.sha1(group[f"sar/{sensor}/image"][...].tobytes()).hexdigest())
"""


@pytest.mark.slow
def test_compiled_kernels_give_the_same_bytes_fresh_or_from_the_cache(tmp_path):
    # The first run compiles every numba kernel into an empty cache, the second loads them:
    # the SAR images must not change (fastmath made a few pixels round differently).
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba-cache"))
    digests = []
    for run in ("fresh", "cached"):
        done = subprocess.run([sys.executable, "-c", _SYNTH_SAR_DIGEST, str(tmp_path / run)], env=env,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        digests.append(done.stdout.split())
    assert len(digests[0]) == 4
    assert digests[0] == digests[1]
