"""Whole synthetic datasets: validity, determinism, resume and refusal, the CLI."""

import json
import pathlib
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from zendar_dataset.errors import ZendarError
from zendar_dataset.format.validate import validate_dataset
from zendar_dataset.sim.generate import SceneSynthesisError, split_scene_ids, synthesize_dataset


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


def _files(root):
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def _temporaries(root):
    return [p.name for p in (root / "scenes").iterdir() if ".tmp-" in p.name]


@pytest.mark.slow
def test_same_seed_gives_byte_identical_valid_datasets_whatever_the_jobs(tmp_path):
    a = synthesize_dataset(tmp_path / "a", "tiny", n_scenes=2, seed=7, progress=False, jobs=1)
    b = synthesize_dataset(tmp_path / "b", "tiny", n_scenes=2, seed=7, progress=False, jobs=2)
    assert validate_dataset(a) == []
    arrays_a, arrays_b = _arrays(a), _arrays(b)
    assert arrays_a.keys() == arrays_b.keys() and len(arrays_a) > 20
    for key in arrays_a:
        assert arrays_a[key].tobytes() == arrays_b[key].tobytes(), key
    # Not only the arrays: every file, metadata included.
    files_a, files_b = _files(a), _files(b)
    assert files_a.keys() == files_b.keys()
    assert [name for name in files_a if files_a[name] != files_b[name]] == []
    assert arrays_a["scene-0000.zarr/labels/moving_cars/x"].size > 0
    assert not np.array_equal(arrays_a["scene-0000.zarr/tracklog/position_ecef"], arrays_a["scene-0001.zarr/tracklog/position_ecef"])


@pytest.mark.slow
def test_ctrl_c_and_a_failing_worker_leave_no_partial_scene_and_a_rerun_finishes(tmp_path):
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "zendar_dataset.cli.data", "synth", str(out), "--profile", "tiny", "--scenes", "2",
           "--split-ratios", "0.5,0,0.5", "--withhold-test-labels", "--jobs", "2", "--quiet"]
    # SIGINT's disposition set explicitly: under nohup or `cmd &` pytest inherits it ignored.
    process = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while not ((out / "scenes").is_dir() and _temporaries(out)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _temporaries(out), "no scene was started"
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130 and "interrupted" in stderr, stderr
    assert _temporaries(out) == [] and not (out / "dataset.json").exists()
    # Resume, but scene-0001's ground truth cannot be written: a directory of the user's is in the way.
    blocker = out / "ground_truth" / "scene-0001.json"
    blocker.mkdir(parents=True)
    (blocker / "mine.txt").write_text("keep me")
    kwargs = dict(profile="tiny", n_scenes=2, seed=0, split_ratios=(0.5, 0.0, 0.5), progress=False,
                  withhold_test_labels=True, jobs=2)
    with pytest.raises(SceneSynthesisError, match="scene-0001: .*Error") as caught:
        synthesize_dataset(out, **kwargs)
    assert caught.value.scene_id == "scene-0001"
    # The scene in progress in the other worker was finished and kept.
    assert (out / "scenes" / "scene-0000.zarr").is_dir() and _temporaries(out) == []
    assert (blocker / "mine.txt").read_text() == "keep me"
    shutil.rmtree(blocker)
    finished = subprocess.run(cmd, capture_output=True, text=True)
    assert finished.returncode == 0, finished.stderr
    assert validate_dataset(out) == []
    assert sorted(p.name for p in (out / "scenes").iterdir()) == ["scene-0000.zarr", "scene-0001.zarr"]
    frames = json.loads((out / "test_ground_truth.json").read_text())["frames"]
    assert frames and all(key.startswith("scene-0001/") for key in frames)


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
    # Interrupted run: one scene missing, the temporary store of a process that is gone left behind
    # (named by the package in a child process that then exited); re-running finishes the scene and
    # removes that temporary, but not a user's entry that merely looks like one.
    mtime = (out / "scenes" / "scene-0000.h5").stat().st_mtime_ns
    (out / "scenes" / "scene-0001.h5").unlink()
    named = subprocess.run(
        [sys.executable, "-c", "import sys; from zendar_dataset.temporary_files import temporary_sibling; "
         "print(temporary_sibling(sys.argv[1]))", str(out / "scenes" / "scene-0001.h5")],
        capture_output=True, text=True, check=True,
    )
    stale = pathlib.Path(named.stdout.strip())
    stale.write_bytes(b"partial")
    lookalike = out / "scenes" / ".scene-0001.h5.tmp-mine"
    lookalike.write_bytes(b"the user's")
    again = subprocess.run(cmd, capture_output=True, text=True)
    assert again.returncode == 0, again.stderr
    assert (out / "scenes" / "scene-0001.h5").exists()
    assert not stale.exists() and lookalike.read_bytes() == b"the user's"
    lookalike.unlink()
    assert (out / "scenes" / "scene-0000.h5").stat().st_mtime_ns == mtime
    # Other settings, or a user's directory: refused with exit 2 and nothing touched.
    other = subprocess.run(cmd[:-6] + ["--seed", "2", "--quiet"], capture_output=True, text=True)
    assert other.returncode == 2 and "other settings" in other.stderr
    no_jobs = subprocess.run(cmd + ["--jobs", "0"], capture_output=True, text=True)
    assert no_jobs.returncode == 2 and "--jobs" in no_jobs.stderr
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


def test_duration_option_shortens_scenes_is_recorded_and_is_part_of_the_resume_key(tmp_path, capsys):
    from zendar_dataset.cli.data import main
    from zendar_dataset.format import open_dataset

    out = tmp_path / "short"
    assert main(["synth", str(out), "--profile", "tiny", "--scenes", "1", "--duration-s", "0.5", "--quiet"]) == 0
    recorded = json.loads((out / "simulation.json").read_text())["profile"]
    assert recorded["scene_duration_s"] == 0.5
    assert "0.5 s scenes instead of the profile's 1 s" in recorded["reductions"]
    with open_dataset(out).open_scene("scene-0000") as scene:
        # SAR frames come at 10 Hz from half a period in: 0.05, 0.15, ..., 0.45 s.
        sar_ns = scene.timestamps("sar/front_left")
        radar_ns = [scene.timestamps(f"radar/{s}") for s in ("front_left", "front_right")]
    assert len(sar_ns) == 5 and np.allclose(np.diff(sar_ns), 1e8)
    assert (max(int(r[-1]) for r in radar_ns) - min(int(r[0]) for r in radar_ns)) / 1e9 < 0.5
    capsys.readouterr()
    # Resuming with another length is another dataset: refused, nothing changed.
    before = _files(out)
    assert main(["synth", str(out), "--profile", "tiny", "--scenes", "1", "--quiet"]) == 2
    assert "other settings" in capsys.readouterr().err and _files(out) == before
    assert main(["synth", str(tmp_path / "partial"), "--profile", "tiny", "--duration-s", "0.75", "--quiet"]) == 2
    assert "whole number of SAR frame periods" in capsys.readouterr().err and not (tmp_path / "partial").exists()
    for bad in ("0.2", "nan", "-1", "inf"):
        assert main(["synth", str(tmp_path / f"bad{bad}"), "--profile", "tiny", "--duration-s", bad, "--quiet"]) == 2
        assert "scene duration" in capsys.readouterr().err
        assert not (tmp_path / f"bad{bad}").exists()
