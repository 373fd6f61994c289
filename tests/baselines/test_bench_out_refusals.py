"""``zendar-bench``'s outputs never land in the dataset it reads nor over a user's files: refused with
exit 2, naming the path, before anything is written."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from zendar_dataset.sim.generate import synthesize_dataset
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.temporary_files import forget, temporary_sibling

from zendar_baselines.bench.cli import main as bench_main


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Two short scenes, one in train and one in test (each split labelled)."""
    root = tmp_path_factory.mktemp("refusals") / "data"
    synthesize_dataset(root, profile=get_profile("tiny").with_duration(0.5), n_scenes=2, split_ratios=(0.5, 0.0, 0.5),
                       progress=False)
    return root


def _tree(root: Path) -> list[tuple[str, int]]:
    """Every entry under ``root`` with its size (0 for a directory), to show that nothing changed."""
    return sorted((str(path.relative_to(root)), path.stat().st_size if path.is_file() else 0)
                  for path in root.rglob("*"))


@pytest.mark.parametrize("route", ["direct", "linked data", "linked out", "out is the data"])
def test_run_refuses_an_out_inside_its_dataset_before_writing(dataset, tmp_path, monkeypatch, capsys, route):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    data, out = dataset, dataset / "benchout"
    if route == "linked data":
        data = tmp_path / "link"
        data.symlink_to(dataset, target_is_directory=True)
        out = data / "benchout"
    elif route == "linked out":
        out = tmp_path / "outlink"
        out.symlink_to(dataset / "scenes", target_is_directory=True)
    elif route == "out is the data":
        out = dataset
    before = _tree(dataset)
    assert bench_main(["--quick", "--data", str(data), "--out", str(out)]) == 2
    message = capsys.readouterr().err
    assert f"--out {str(out)!r} is inside the dataset" in message and "Traceback" not in message
    assert _tree(dataset) == before


def test_run_refuses_an_out_inside_the_dataset_it_would_simulate(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    assert bench_main(["--quick", "--data", str(tmp_path / "new"), "--out", str(tmp_path / "new" / "out")]) == 2
    assert "is inside the dataset" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # nothing simulated


@pytest.mark.parametrize("name", ["quality.json", "notes.txt"])
def test_autolabels_refuses_an_out_holding_a_users_file(dataset, tmp_path, capsys, name):
    out = tmp_path / "al"
    out.mkdir()
    (out / name).write_text("my quality notes\n")
    assert bench_main(["autolabels", str(dataset), "--out", str(out), "--split", "test"]) == 2
    message = capsys.readouterr().err
    assert f"--out {out} holds files that zendar-bench autolabels did not write ({name})" in message
    assert [entry.name for entry in out.iterdir()] == [name] and (out / name).read_text() == "my quality notes\n"


def test_autolabels_refuses_an_out_that_is_a_file(dataset, tmp_path, capsys):
    out = tmp_path / "al"
    out.write_text("mine\n")
    assert bench_main(["autolabels", str(dataset), "--out", str(out), "--split", "test"]) == 2
    assert f"--out {out}: exists and is not a directory" in capsys.readouterr().err
    assert out.read_text() == "mine\n"


def test_autolabels_reruns_into_its_own_out(dataset, tmp_path, capsys):
    out = tmp_path / "al"
    assert bench_main(["autolabels", str(dataset), "--out", str(out), "--split", "test"]) == 0
    first = json.loads((out / "quality.json").read_text())
    # A temporary a killed run left is its own too; the re-run removes it.
    leftover = temporary_sibling(out / "quality.json")
    leftover.write_text("{")
    forget(leftover)  # as if its process had died
    assert bench_main(["autolabels", str(dataset), "--out", str(out), "--split", "test"]) == 0, capsys.readouterr().err
    assert json.loads((out / "quality.json").read_text()) == first
    assert bench_main(["autolabels", str(dataset), "--out", str(out), "--split", "test", "--no-quality"]) == 0
    assert sorted(entry.name for entry in out.iterdir()) == ["quality.json", "store"]
