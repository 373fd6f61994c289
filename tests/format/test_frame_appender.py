"""Frames appended straight to raw zarr chunk files are stored exactly as zarr stores them, and the
array's metadata is written once rather than once per frame."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest
import zarr

from tests.format.conftest import A, D, ENU_ORIGIN, R, SAR_H, SAR_W, T0_NS, make_calibration
from zendar_dataset.format import SceneWriter, stores


def _files(root: pathlib.Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file() and p.name != "zarr.json"}


def test_appended_frames_are_the_chunk_files_zarr_writes(tmp_path):
    rng = np.random.default_rng(3)
    cubes = (rng.standard_normal((3, R, D, A)) + 1j * rng.standard_normal((3, R, D, A))).astype(np.complex64)
    images = rng.integers(0, 2**32, size=(3, SAR_H, SAR_W), dtype=np.uint32)
    with SceneWriter(tmp_path / "s.zarr", "s0", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        for k in range(3):
            t = T0_NS + k * 100_000_000
            writer.append_radar("left", t, cubes[k])
            writer.append_sar("left", t, images[k], [6e6, 0, 0], [0.04, 0, 0], [0, 0.04, 0], [t, t], magnitude_only=True)
    for path, data in (("radar/left/cube", cubes), ("sar/left/image", images)):
        reference = zarr.open_group(str(tmp_path / "ref.zarr"), mode="a").create_array(
            path, shape=data.shape, dtype=data.dtype, chunks=(1, *data.shape[1:]), compressors=None, fill_value=0
        )
        reference[...] = data
        written = zarr.open_array(str(tmp_path / "s.zarr" / path), mode="r")
        assert written.shape == data.shape
        np.testing.assert_array_equal(written[...], data)
        assert _files(tmp_path / "s.zarr" / path) == _files(tmp_path / "ref.zarr" / path)


def test_the_metadata_of_a_raw_frame_array_is_written_at_creation_and_at_the_end_only(tmp_path, monkeypatch):
    root = zarr.open_group(str(tmp_path / "a.zarr"), mode="w")
    array = stores.create_array(root, "sar/left/image", shape=(0, SAR_H, SAR_W), dtype=np.dtype(np.uint32),
                                chunks=(1, SAR_H, SAR_W), kind=stores.RAW, resizable=True)
    resizes = []
    monkeypatch.setattr(zarr.Array, "resize", lambda self, shape: resizes.append(shape))
    appender = stores.FrameAppender(array)
    for k in range(5):
        appender.append(np.full((SAR_H, SAR_W), k, np.uint32))
    assert resizes == []
    appender.finish()
    assert resizes == [(5, SAR_H, SAR_W)]


@pytest.mark.parametrize("suffix", [".h5", ".zarr"])
def test_frames_of_other_arrays_go_through_the_backend(tmp_path, suffix):
    path = tmp_path / f"a{suffix}"
    store = stores.create_store(path, stores.backend_from_path(path))
    try:
        # Compressed (camera kind): not a raw chunk file, so the backend writes it.
        array = stores.create_array(store.root, "camera/front/image", shape=(0, 4, 6, 3), dtype=np.dtype(np.uint8),
                                    chunks=(1, 4, 6, 3), kind=stores.FAST, resizable=True)
        appender = stores.FrameAppender(array)
        for k in range(3):
            appender.append(np.full((4, 6, 3), k, np.uint8))
        appender.finish()
        assert array.shape == (3, 4, 6, 3) and [int(array[k][0, 0, 0]) for k in range(3)] == [0, 1, 2]
    finally:
        store.close()
