"""Whole synthetic datasets: validity, determinism, resume and refusal, the CLI."""

import json
import subprocess
import sys

import numpy as np
import pytest

from zendar_dataset.errors import ZendarError
from zendar_dataset.format.validate import validate_dataset
from zendar_dataset.sim.generate import split_scene_ids, synthesize_dataset


def _arrays(root):
    import zarr

    out = {}
    for path in sorted((root / "scenes").glob("*.zarr")):
        group = zarr.open_group(str(path), mode="r")

        def visit(g, prefix):
            for key in sorted(g.keys()):
                item = g[key]
                if hasattr(item, "shape") and hasattr(item, "dtype"):
                    out[f"{path.name}/{prefix}{key}"] = np.asarray(item[...])
                else:
                    visit(item, f"{prefix}{key}/")
        visit(group, "")
    return out


@pytest.mark.slow
def test_same_seed_gives_byte_identical_valid_datasets(tmp_path):
    a = synthesize_dataset(tmp_path / "a", "tiny", n_scenes=1, seed=7, progress=False)
    b = synthesize_dataset(tmp_path / "b", "tiny", n_scenes=1, seed=7, progress=False)
    assert validate_dataset(a) == []
    arrays_a, arrays_b = _arrays(a), _arrays(b)
    assert arrays_a.keys() == arrays_b.keys() and len(arrays_a) > 10
    for key in arrays_a:
        assert arrays_a[key].tobytes() == arrays_b[key].tobytes(), key
    labels = arrays_a["scene-0000.zarr/labels/moving_cars/x"]
    assert labels.size > 0


@pytest.mark.slow
def test_cli_writes_a_valid_dataset_resumes_and_refuses_foreign_directories(tmp_path):
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "zendar_dataset.cli.data", "synth", str(out), "--profile", "tiny", "--scenes", "3",
           "--seed", "1", "--quiet", "--withhold-test-labels", "--backend", "hdf5"]
    done = subprocess.run(cmd, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert validate_dataset(out) == []
    document = json.loads((out / "dataset.json").read_text())
    assert document["splits"] == {"train": ["scene-0000"], "val": ["scene-0001"], "test": ["scene-0002"]}
    ground_truth = json.loads((out / "test_ground_truth.json").read_text())
    assert all(key.startswith("scene-0002/") for key in ground_truth["frames"]) and ground_truth["frames"]
    # Interrupted run: one scene missing, a temporary store left behind; re-running finishes it.
    mtime = (out / "scenes" / "scene-0000.h5").stat().st_mtime_ns
    (out / "scenes" / "scene-0001.h5").unlink()
    (out / "scenes" / ".scene-0001.h5.tmp-1-dead").write_bytes(b"partial")
    again = subprocess.run(cmd, capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert (out / "scenes" / "scene-0001.h5").exists()
    assert not (out / "scenes" / ".scene-0001.h5.tmp-1-dead").exists()
    assert (out / "scenes" / "scene-0000.h5").stat().st_mtime_ns == mtime
    # Other settings, or a user's directory: refused with exit 2 and nothing touched.
    other = subprocess.run(cmd[:-6] + ["--seed", "2", "--quiet"], capture_output=True, text=True)
    assert other.returncode == 2 and "other settings" in other.stderr
    user_dir = tmp_path / "mine"
    user_dir.mkdir()
    (user_dir / "notes.txt").write_text("keep me")
    refused = subprocess.run(cmd[:4] + [str(user_dir), "--profile", "tiny", "--quiet"], capture_output=True, text=True)
    assert refused.returncode == 2 and "not empty" in refused.stderr
    assert (user_dir / "notes.txt").read_text() == "keep me"


def test_split_ratios_assign_every_scene_once():
    splits = split_scene_ids(10, (0.6, 0.2, 0.2))
    assert [len(splits[s]) for s in ("train", "val", "test")] == [6, 2, 2]
    assert sorted(sum(splits.values(), [])) == [f"scene-{i:04d}" for i in range(10)]
    with pytest.raises(ZendarError):
        split_scene_ids(3, (1.0, -1.0, 0.0))
