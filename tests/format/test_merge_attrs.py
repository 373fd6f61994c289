"""Attributes merged into a node's metadata directly are what zarr's own update writes; HDF5 and absent
nodes go through the backend."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

from zendar_dataset.format import stores


def _store_with_nodes(path):
    store = stores.create_store(path, "zarr" if path.suffix == ".zarr" else "hdf5")
    stores.write_attrs(store.root.require_group("sar/left"), {"serial": "A", "nested": {"k": [1, 2]}})
    stores.create_array(store.root, "sar/left/image", shape=(0, 2, 2), dtype=np.dtype(np.uint32), chunks=(1, 2, 2),
                        kind=stores.RAW, resizable=True)
    return store


def test_merged_attributes_are_the_bytes_zarr_writes(tmp_path):
    mine, theirs = _store_with_nodes(tmp_path / "mine.zarr"), _store_with_nodes(tmp_path / "theirs.zarr")
    new = {"nested": {"k": [3]}, "aperture_known": False, "crc32c": "00ff", "nan": float("nan")}
    for path in ("", "sar/left", "sar/left/image"):
        stores.merge_attrs(mine.root, path, new)
        node = theirs.root if not path else theirs.root[path]
        stores.write_attrs(node, new)  # zarr's update_attributes
        assert (tmp_path / "mine.zarr" / path / "zarr.json").read_bytes() == (tmp_path / "theirs.zarr" / path / "zarr.json").read_bytes()
    opened = zarr.open_group(str(tmp_path / "mine.zarr"), mode="r")
    assert opened["sar/left"].attrs["serial"] == "A" and opened["sar/left"].attrs["nested"] == {"k": [3]}
    assert opened["sar/left/image"].attrs["crc32c"] == "00ff"


@pytest.mark.parametrize("suffix", [".zarr", ".h5"])
def test_a_node_not_there_becomes_a_group_and_hdf5_goes_through_h5py(tmp_path, suffix):
    store = _store_with_nodes(tmp_path / f"s{suffix}")
    stores.merge_attrs(store.root, "lidar/top", {"points_frame": "enu"})
    stores.merge_attrs(store.root, "sar/left/image", {"crc32c": "01"})
    stores.merge_attrs(store.root, "sar/left", {"magnitude_only": True})
    assert stores.read_attrs(store.root["lidar/top"]) == {"points_frame": "enu"}
    assert stores.read_attrs(store.root["sar/left/image"])["crc32c"] == "01"
    assert stores.read_attrs(store.root["sar/left"]) == {"serial": "A", "nested": {"k": [1, 2]}, "magnitude_only": True}
    store.close()
