"""The optional per-frame SAR flag ``ego_stopped``: written for every frame or none, read back, validated."""

from __future__ import annotations

import numpy as np
import pytest

from tests.format.conftest import ENU_ORIGIN, SAR_H, SAR_W, T0_NS, make_calibration
from tests.format.helpers import open_raw, reconsolidate
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import SceneReader, SceneWriter
from zendar_dataset.format.validate import validate_scene

ORIGIN = np.array([-2_700_000.0, -4_290_000.0, 3_850_000.0])


def _append(writer, k: int, ego_stopped=None) -> None:
    t = T0_NS + k * 100_000_000
    image = np.zeros((SAR_H, SAR_W), np.complex64)
    writer.append_sar("left", t, image, ORIGIN, [0.04, 0, 0], [0, 0.04, 0], [t - 5, t + 5], ego_stopped=ego_stopped)


@pytest.mark.parametrize("suffix", [".zarr", ".h5"])
def test_ego_stopped_round_trips_and_validates(tmp_path, suffix):
    path = tmp_path / f"scene{suffix}"
    with SceneWriter(path, "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        for k, flag in enumerate([False, True, True, False]):
            _append(writer, k, flag)
    assert validate_scene(path) == []
    with SceneReader(path) as scene:
        flags = scene.array("sar/left/ego_stopped")[...]
    assert flags.dtype == np.bool_ and flags.tolist() == [False, True, True, False]


def test_a_stream_without_the_flag_stays_valid_and_mixing_is_refused(tmp_path):
    path = tmp_path / "scene.zarr"
    with SceneWriter(path, "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        _append(writer, 0)
        with pytest.raises(ZendarFormatError, match="ego_stopped: expected a value for every frame"):
            _append(writer, 1, True)
        _append(writer, 1)
    assert validate_scene(path) == []
    with SceneReader(path) as scene:
        assert not scene.has("sar/left/ego_stopped")
    with SceneWriter(tmp_path / "b.zarr", "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        _append(writer, 0, False)
        with pytest.raises(ZendarFormatError, match="ego_stopped: expected a value for every frame"):
            _append(writer, 1)
        with pytest.raises(ZendarFormatError, match="expected a bool"):
            _append(writer, 1, 1)


def test_validate_names_a_flag_of_the_wrong_dtype_or_length(tmp_path):
    path = tmp_path / "scene.zarr"
    with SceneWriter(path, "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        for k in range(3):
            _append(writer, k, False)
    root = open_raw(path, "r+")
    del root["sar/left/ego_stopped"]
    root.create_array("sar/left/ego_stopped", data=np.zeros(2, np.int8))
    reconsolidate(path)
    problems = validate_scene(path)
    assert any("sar/left/ego_stopped: expected dtype bool, found int8" in p for p in problems), problems
    assert any("sar/left/ego_stopped: expected 3 rows" in p for p in problems), problems
