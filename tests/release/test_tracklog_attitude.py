"""The tracklog's ``Position.attitude`` convention (IMU forward-right-down -> ECEF) is checked against the
local vertical and the direction of travel before anything is written: a z-up or backwards attitude is
refused with its evidence, the paper's convention is recorded as checked."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.release.fixture import build_release, enu_to_ecef, vehicle, wxyz
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.release.tracklog_attitude import attitude_evidence, check_attitude

# Axes in forward-right-down: x forward, y left, z up (180 degrees about x), and an IMU mounted backwards
# (180 degrees about z: x backward, y left, z down).
FLU = np.diag([1.0, -1.0, -1.0])
BACKWARDS = np.diag([-1.0, -1.0, 1.0])
SCENE = "2020-02-03_2252_001"


def run(*args, capsys) -> tuple[int, str, str]:
    from zendar_dataset.cli.data import main

    status = main([str(a) for a in args])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_the_papers_convention_is_imported_and_recorded_as_checked(tmp_path, capsys):
    n = len(build_release(tmp_path / "release").tracklog_s)  # poses at 50 Hz over 2.4 s, all at 8 m/s
    status, _, err = run("import-release", tmp_path / "release", tmp_path / "out", capsys=capsys)
    assert status == 0, err
    (scene,) = json.loads((tmp_path / "out" / "release_import.json").read_text())["scenes"]
    (checked,) = [text for text in scene["assumptions"] if text.startswith("Position.attitude checked against the path")]
    assert f"its third (down) axis lies against the local downward vertical in 0 of {n} records (median cosine +1.00" in checked
    assert f"its first (forward) axis lies against the direction of travel in 0 of {n} records (median cosine +1.00" in checked


@pytest.mark.parametrize(("axes", "refuted", "kept"), [
    (FLU, "third (down) axis lies against the local downward vertical", "first (forward) axis lies against the direction of travel"),
    (BACKWARDS, "first (forward) axis lies against the direction of travel", "third (down) axis lies against the local downward vertical"),
])
def test_another_convention_is_refused_with_its_evidence_and_nothing_written(tmp_path, capsys, axes, refuted, kept):
    n = len(build_release(tmp_path / "release", tracklog_axes=axes).tracklog_s)
    status, _, err = run("import-release", tmp_path / "release", tmp_path / "out", capsys=capsys)
    assert status == 2 and "Traceback" not in err
    assert f"{SCENE}: the tracklog's Position.attitude is not IMU (forward, right, down) -> ECEF" in err
    assert f"{refuted} in {n} of {n} records (median cosine -1.00" in err and f"{kept} in 0 of {n} records" in err
    assert "does not guess another convention" in err
    assert not (tmp_path / "out" / "scenes").exists() or not any((tmp_path / "out" / "scenes").iterdir())


def _track(times_s, axes=np.eye(3), speed_scale=1.0):
    poses = [vehicle(speed_scale * t) for t in times_s]
    positions = np.array([enu_to_ecef(p) for p, _, _ in poses])
    attitudes = np.array([wxyz(rotation @ axes) for _, rotation, _ in poses])
    return np.asarray(times_s, float), positions, attitudes


def test_a_standing_vehicle_says_nothing_about_forward_and_a_few_odd_records_do_not_decide():
    times = np.arange(0.0, 2.0, 0.02)
    t, p, q = _track(times, speed_scale=0.0)  # parked: one position, the right attitude
    down, forward = attitude_evidence(t, p, q)
    assert down.records == times.size and down.contradicting == 0 and forward.records == 0
    assert check_attitude("s", down, forward).endswith("its first (forward) axis: no record to compare with the direction of travel")
    t, p, q = _track(times)
    q[:20] = wxyz(vehicle(0.0)[1] @ FLU)  # a fifth of the records z-up: not decisive
    down, forward = attitude_evidence(t, p, q)
    assert down.contradicting == 20 and not down.refutes
    q[:] = wxyz(vehicle(0.0)[1] @ FLU)
    with pytest.raises(ZendarFormatError, match=r"third \(down\) axis lies against the local downward vertical in 100 of 100"):
        check_attitude("s", *attitude_evidence(t, p, q))
