"""Where the simulator backprojects its SAR images: the numba kernel (default) or torch on a GPU.

Both compute the same float32 sum; the torch backend is checked here on the CPU against the numba
kernel on a real simulated frame, and on CUDA where a GPU exists."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
import torch

from zendar_dataset.errors import ZendarError
from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.sim.generate import check_sar_device, synthesize_dataset
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.scene import build_scene, simulate_sar, stream_rng

CUDA = torch.cuda.is_available()


def _frame(device):
    profile = get_profile("tiny")
    truth = build_scene(profile, 0, 0)
    written = truth.tracklog_written
    tracklog = PoseInterpolator(written.timestamp_ns, written.position_ecef, written.attitude_wxyz)
    return simulate_sar(truth, profile, "front_right", 0.55, stream_rng(0, 0, "sar_front_right"), tracklog, device)


def _agree(image, reference):
    assert image.dtype == np.complex64 and image.shape == reference.shape
    # The same float32 sum in another order: 1.1e-4 of the brightest pixel at most and 6e-5 in L2
    # measured (-79 / -84 dB); an error in either backend's geometry or phase would be of order 1.
    error = np.abs(image - reference).max() / np.abs(reference).max()
    assert error < 5e-4, error
    assert np.linalg.norm(image - reference) / np.linalg.norm(reference) < 2e-4


def test_torch_backend_forms_the_same_simulated_image_as_the_numba_kernel(monkeypatch):
    from zendar_dataset.sim import sar_formation

    reference, grid, aperture = _frame(None)
    assert np.array_equal(_frame("cpu")[0].view(np.uint64), reference.view(np.uint64))  # "cpu" is the kernel
    # What --device cuda runs, on the CPU: the torch backend inside the simulator's own call.
    numba_call = sar_formation.backproject
    monkeypatch.setattr(sar_formation, "backproject",
                        lambda *args, **kwargs: numba_call(*args, **{**kwargs, "backend": "torch", "device": "cpu"}))
    image, grid_torch, aperture_torch = _frame(None)
    _agree(image, reference)
    np.testing.assert_array_equal(grid.origin, grid_torch.origin)
    assert aperture == aperture_torch


def test_device_names_are_checked_before_anything_is_written(tmp_path):
    assert check_sar_device(None) is None and check_sar_device("cpu") is None
    for bad in ("gpu", "cuda:x", 3, "mps"):
        with pytest.raises(ZendarError, match="SAR device"):
            check_sar_device(bad)
    with pytest.raises(ZendarError, match="SAR device"):
        synthesize_dataset(tmp_path / "out", "tiny", n_scenes=1, progress=False, sar_device="cuda:99")
    assert not (tmp_path / "out").exists()


@pytest.mark.skipif(CUDA, reason="checks the refusal on a machine without CUDA")
def test_cli_refuses_cuda_without_a_gpu_with_exit_2(tmp_path):
    executable = shutil.which("zendar-data")
    command = [executable] if executable else [sys.executable, "-m", "zendar_dataset.cli.data"]
    done = subprocess.run([*command, "synth", str(tmp_path / "out"), "--profile", "tiny", "--device", "cuda", "--quiet"],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr
    assert "no such CUDA device" in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "out").exists()


def test_a_cpu_run_records_no_device(tmp_path):
    out = synthesize_dataset(tmp_path / "out", "tiny", n_scenes=1, progress=False, sar_device="cpu")
    assert "sar_device" not in json.loads((out / "simulation.json").read_text())


@pytest.mark.gpu
@pytest.mark.skipif(not CUDA, reason="needs a CUDA GPU")
def test_cuda_forms_the_same_image_and_is_recorded(tmp_path):
    reference, _, _ = _frame(None)
    image, _, _ = _frame("cuda")
    _agree(image, reference)
    out = synthesize_dataset(tmp_path / "out", "tiny", n_scenes=1, progress=False, sar_device="cuda")
    assert json.loads((out / "simulation.json").read_text())["sar_device"] == "cuda"
    with pytest.raises(ZendarError, match="other settings"):
        synthesize_dataset(tmp_path / "out", "tiny", n_scenes=1, progress=False)
