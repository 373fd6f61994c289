"""Interrupted writes leave nothing that looks complete; nothing a user owns is replaced silently."""

from __future__ import annotations

import json
import os
import pathlib

import numpy as np
import pytest

from tests.format.conftest import ENU_ORIGIN, T0_NS, A, D, R, make_calibration, write_scene
from zendar_dataset.errors import ZendarFormatError
from zendar_dataset.format import DatasetWriter, SceneReader, SceneWriter, open_dataset


class Interrupted(Exception):
    pass


def test_exception_inside_scene_leaves_no_scene_and_no_entry(tmp_path, backend):
    rng = np.random.default_rng(0)
    writer = DatasetWriter(tmp_path, "t", backend=backend)
    with writer.scene("good", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as scene:
        write_scene(scene, rng)
    with pytest.raises(Interrupted):
        with writer.scene("broken", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as scene:
            write_scene(scene, rng)
            raise Interrupted
    assert not writer.scene_path("broken").exists()
    assert [p.name for p in (tmp_path / "scenes").iterdir()] == [writer.scene_path("good").name]
    with pytest.raises(ZendarFormatError, match="scene 'broken' is not complete"):
        writer.finalize({"train": ["good", "broken"]})
    assert not (tmp_path / "dataset.json").exists()
    writer.finalize({"train": ["good"]})
    document = json.loads((tmp_path / "dataset.json").read_text())
    assert list(document["scenes"]) == ["good"] and document["splits"] == {"train": ["good"], "val": [], "test": []}
    assert open_dataset(tmp_path).open_scene("good").labels() is not None


def test_scene_is_invisible_until_closed(tmp_path):
    path = tmp_path / "x.zarr"
    writer = SceneWriter(path, "x", enu_origin=ENU_ORIGIN, calibration=make_calibration())
    writer.append_radar("left", T0_NS, np.zeros((R, D, A), np.complex64))
    assert not path.exists()
    writer.close()
    assert path.exists() and writer.completed
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.zarr"]


def test_failure_at_close_removes_the_temporary_store(tmp_path):
    path = tmp_path / "x.h5"
    with pytest.raises(ZendarFormatError, match="expected timestamps of the first SAR stream"):
        with SceneWriter(path, "x", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
            fields = ("timestamp_ns", "x", "y", "length", "width", "yaw", "vx", "vy", "track_id")
            labels = {k: np.ones(1, dtype=np.int64 if k in ("timestamp_ns", "track_id") else float) for k in fields}
            writer.write_labels(labels)  # refers to a SAR frame that never comes
    assert list(tmp_path.iterdir()) == []


def test_existing_scene_is_not_replaced_without_overwrite(tmp_path, backend):
    suffix = ".zarr" if backend == "zarr" else ".h5"
    path = tmp_path / f"x{suffix}"
    for value in (1, 2):
        if value == 2:
            with pytest.raises(FileExistsError):
                SceneWriter(path, "x", enu_origin=ENU_ORIGIN, calibration=make_calibration())
        with SceneWriter(path, "x", enu_origin=ENU_ORIGIN, calibration=make_calibration(), overwrite=value == 2) as writer:
            writer.append_radar("left", T0_NS, np.full((R, D, A), value, np.complex64))
    assert SceneReader(path).array("radar/left/cube")[0][0, 0, 0] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_dataset_writer_refuses_existing_dataset(tmp_path):
    DatasetWriter(tmp_path, "t").finalize({})
    with pytest.raises(FileExistsError):
        DatasetWriter(tmp_path, "t")
    DatasetWriter(tmp_path, "t", overwrite=True).finalize({})


@pytest.mark.parametrize("failing_call", [1, 2])
def test_an_interrupt_while_the_writer_starts_leaves_no_temporary(tmp_path, backend, monkeypatch, failing_call):
    # Ctrl-C (or a full disk) can land before any ``with`` block owns the temporary store.
    from zendar_dataset.format import stores

    real_merge_attrs = stores.merge_attrs
    calls = []

    def merge_attrs(root, path, attrs):  # the writer's two attribute writes as it starts: root, calibration
        calls.append(attrs)
        if len(calls) == failing_call:
            raise KeyboardInterrupt
        return real_merge_attrs(root, path, attrs)

    monkeypatch.setattr(stores, "merge_attrs", merge_attrs)
    suffix = ".zarr" if backend == "zarr" else ".h5"
    with pytest.raises(KeyboardInterrupt):
        SceneWriter(tmp_path / f"x{suffix}", "x", enu_origin=ENU_ORIGIN, calibration=make_calibration(), backend=backend)
    assert list(tmp_path.iterdir()) == []


def test_an_interrupt_while_an_old_scene_is_swapped_out_keeps_the_old_scene(tmp_path, monkeypatch):
    # A zarr scene is a directory: the old one is moved aside before the new one is renamed in.
    path = tmp_path / "x.zarr"
    with SceneWriter(path, "x", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        writer.append_radar("left", T0_NS, np.full((R, D, A), 1, np.complex64))
    real_replace = os.replace
    renames_onto_the_scene = []

    def replace(src, dst):
        if pathlib.Path(dst) == path:
            renames_onto_the_scene.append(src)
            if len(renames_onto_the_scene) == 1:  # the new scene's rename: Ctrl-C lands here
                raise KeyboardInterrupt
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(KeyboardInterrupt):
        with SceneWriter(path, "x", enu_origin=ENU_ORIGIN, calibration=make_calibration(), overwrite=True) as writer:
            writer.append_radar("left", T0_NS, np.full((R, D, A), 2, np.complex64))
    monkeypatch.undo()
    assert SceneReader(path).array("radar/left/cube")[0][0, 0, 0] == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


@pytest.mark.parametrize("array", [np.float64(3.0), np.zeros((5, 0))], ids=["scalar", "empty-trailing-axis"])
def test_an_extra_array_without_rows_is_refused_by_name(tmp_path, backend, array):
    suffix = ".zarr" if backend == "zarr" else ".h5"
    with SceneWriter(tmp_path / f"x{suffix}", "x", enu_origin=ENU_ORIGIN, calibration=make_calibration()) as writer:
        with pytest.raises(ZendarFormatError, match=r"x/lidar/top/extra: expected an array of rows"):
            writer.write_extra_array("lidar/top/extra", array)
