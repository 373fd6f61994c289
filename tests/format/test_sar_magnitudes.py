"""Magnitude-only SAR images: ``sar/<radar>/image`` as uint32 (or float32) magnitudes, exact, validated,
read alike by every reader path; the older complex64 magnitude layout still reads."""

from __future__ import annotations

import numpy as np
import pytest

from tests.format.conftest import ENU_ORIGIN, SAR_H, SAR_W, T0_NS, make_calibration
from tests.format.helpers import dump, replace_array, set_attr
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import SceneReader, SceneWriter
from zendar_dataset.format.validate import validate_scene
from zendar_dataset.sar.frames import SarFrames

ORIGIN = np.array([-2_700_000.0, -4_290_000.0, 3_850_000.0])
BIG = 2**24 + 1  # 16777217: float32 (and so complex64) rounds it to 16777216


def _image(k: int, dtype: str) -> np.ndarray:
    image = (np.arange(SAR_H * SAR_W).reshape(SAR_H, SAR_W) + 1000 * k).astype(dtype)
    image[1, 2] = BIG if dtype == "uint32" else image[1, 2]
    return image


def _append(writer, sensor: str, k: int, image: np.ndarray, magnitude_only: bool) -> None:
    t = T0_NS + k * 100_000_000
    writer.append_sar(sensor, t, image, ORIGIN + k, [0.04, 0, 0], [0, 0.04, 0], [t - 5, t + 5], magnitude_only=magnitude_only)


def _write(path, frames: int = 3, dtype: str = "uint32") -> None:
    with SceneWriter(path, "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        for k in range(frames):
            _append(writer, "left", k, _image(k, dtype), True)
            _append(writer, "right", k, _image(k, "uint32").astype(np.complex64), False)


@pytest.mark.parametrize("suffix", [".zarr", ".h5"])
@pytest.mark.parametrize("dtype", ["uint32", "float32"])
def test_magnitudes_round_trip_exactly_and_validate(tmp_path, suffix, dtype):
    path = tmp_path / f"scene{suffix}"
    _write(path, dtype=dtype)
    assert validate_scene(path) == []
    arrays, attrs = dump(path)
    assert attrs["sar/left"]["magnitude_only"] is True  # set by the writer itself
    assert "magnitude_only" not in attrs["sar/right"]  # complex streams are written as before
    with SceneReader(path, verify_checksums=True) as scene:
        images = scene.array("sar/left/image")
        assert images.dtype == np.dtype(dtype) and images.shape == (3, SAR_H, SAR_W)
        for k in range(3):
            np.testing.assert_array_equal(images[k], _image(k, dtype))
        assert scene.sar_magnitude_only("left") and not scene.sar_magnitude_only("right")
    if dtype == "uint32":
        assert int(arrays["sar/left/image"][0, 1, 2]) == BIG


def test_a_magnitude_image_takes_half_the_bytes_of_the_complex_layout(tmp_path):
    path = tmp_path / "scene.zarr"
    _write(path, frames=4)
    stored = {side: sum(f.stat().st_size for f in (path / "sar" / side / "image").rglob("*") if f.is_file() and f.name != "zarr.json")
              for side in ("left", "right")}
    with SceneReader(path) as scene:
        nbytes = {side: scene.array(f"sar/{side}/image")[...].nbytes for side in ("left", "right")}
    assert nbytes["left"] == 4 * 4 * SAR_H * SAR_W and nbytes["right"] == 2 * nbytes["left"]
    assert stored["left"] == nbytes["left"] and stored["right"] == nbytes["right"]  # raw chunks, one per frame


def test_sar_frames_read_magnitudes_alike_and_refuse_phase(tmp_path):
    path = tmp_path / "scene.zarr"
    _write(path)
    with SceneReader(path) as scene:
        sar = SarFrames(scene)
        magnitude, floor = sar.magnitude("left", 0)
        assert magnitude.dtype == np.uint32 and int(magnitude[1, 2]) == BIG
        assert np.isfinite(sar.image_db("left", 0)[0]).all() and floor > 0
        np.testing.assert_array_equal(sar.complex_image("right", 1), _image(1, "uint32").astype(np.complex64))
        with pytest.raises(ZendarFormatError, match=r"s0: sar/left/image: expected complex pixels \(phase\), found magnitudes only"):
            sar.complex_image("left", 0)


@pytest.mark.parametrize("suffix", [".zarr", ".h5"])
def test_the_older_complex64_magnitude_layout_still_validates_and_reads(tmp_path, suffix):
    path = tmp_path / f"scene{suffix}"
    with SceneWriter(path, "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        for k in range(2):
            _append(writer, "left", k, _image(k, "uint32").astype(np.complex64), False)
        writer.write_attrs("sar/left", {"magnitude_only": True})
    assert validate_scene(path) == []
    with SceneReader(path) as scene:
        image = scene.array("sar/left/image")[1]
        assert image.dtype == np.complex64 and scene.sar_magnitude_only("left")
        sar = SarFrames(scene)
        np.testing.assert_array_equal(sar.magnitude("left", 1)[0], np.abs(_image(1, "uint32").astype(np.complex64)))
        with pytest.raises(ZendarFormatError, match="found magnitudes only"):
            sar.complex_image("left", 1)


def test_validate_names_a_wrong_dtype_a_wrong_shape_and_a_missing_attribute_at_once(tmp_path):
    path = tmp_path / "scene.zarr"
    _write(path)
    replace_array(path, "sar/left/image", np.ones((3, SAR_H, SAR_W), np.int16))
    replace_array(path, "sar/right/image", np.ones((4, SAR_H, SAR_W), np.uint32))  # M is 3
    problems = validate_scene(path, "s0")
    expected = [
        "s0: sar/left/image: expected dtype complex64 (or uint32, float32 for a magnitude-only image), found int16",
        "s0: sar/right/image: expected 3 rows",
        "s0: sar/right/image: expected attribute magnitude_only true on sar/right for an image of uint32 magnitudes, found none",
    ]
    for message in expected[:2]:
        assert any(p.startswith(message) for p in problems), problems
    # The attribute is checked on an image whose metadata passed; give right the right rows to see it.
    replace_array(path, "sar/right/image", np.ones((3, SAR_H, SAR_W), np.uint32))
    problems = validate_scene(path, "s0")
    assert expected[0] in problems and expected[2] in problems, problems
    with pytest.raises(ZendarFormatError, match="magnitude_only true on sar/right"):
        SceneReader(path)


@pytest.mark.parametrize("value", [False, "yes"])
def test_validate_refuses_magnitudes_unless_magnitude_only_is_true(tmp_path, value):
    path = tmp_path / "scene.zarr"
    _write(path)
    set_attr(path, "sar/left", "magnitude_only", value)
    problems = validate_scene(path, "s0")
    if value is False:
        assert problems == [
            "s0: sar/left/image: expected attribute magnitude_only true on sar/left for an image of uint32 magnitudes, found False"
        ]
    else:
        assert problems == ["s0: sar/left: expected attribute magnitude_only true or false, found 'yes'"]


def test_the_writer_refuses_complex_magnitudes_and_mixed_dtypes(tmp_path):
    with SceneWriter(tmp_path / "s.zarr", "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        with pytest.raises(ZendarFormatError, match=r"sar/left/image: expected real magnitudes \(uint32 or float32\) .* found complex64"):
            _append(writer, "left", 0, _image(0, "uint32").astype(np.complex64), True)
        _append(writer, "left", 0, _image(0, "uint32"), True)
        with pytest.raises(ZendarFormatError, match="expected every frame of the stream as uint32 .* found float32"):
            _append(writer, "left", 1, _image(1, "float32"), True)
        with pytest.raises(ZendarFormatError, match="expected every frame of the stream as uint32 .* found complex64"):
            _append(writer, "left", 1, _image(1, "uint32"), False)
        _append(writer, "left", 1, _image(1, "uint32"), True)  # the refusals left the stream consistent
    with SceneReader(tmp_path / "s.zarr") as scene:
        assert scene.timestamps("sar/left").shape == (2,) and scene.array("sar/left/image").shape == (2, SAR_H, SAR_W)
