"""The bench's --out: someone else's files are never touched; finished steps are reused, stale ones redone."""

from __future__ import annotations

import pytest

from zendar_baselines.bench.run_directory import RUN_MARKER, RunDirectory
from zendar_dataset.errors import ZendarError


def test_a_directory_of_other_files_is_refused_and_left_as_it_was(tmp_path):
    (tmp_path / "thesis.tex").write_bytes(b"\\documentclass{article}")
    (tmp_path / "figures").mkdir()
    with pytest.raises(ZendarError, match=r"holds files that zendar-bench did not write \(figures, thesis.tex\)"):
        RunDirectory(tmp_path, {"config": "tiny"})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figures", "thesis.tex"]
    assert (tmp_path / "thesis.tex").read_bytes() == b"\\documentclass{article}"


def test_a_run_of_another_config_is_refused(tmp_path):
    RunDirectory(tmp_path / "out", {"config": "tiny"})
    with pytest.raises(ZendarError, match="holds a zendar-bench run of .*tiny.*choose another --out"):
        RunDirectory(tmp_path / "out", {"config": "demo"})
    (tmp_path / "file").write_text("x")
    with pytest.raises(ZendarError, match="exists and is not a directory"):
        RunDirectory(tmp_path / "file", {"config": "tiny"})


def test_a_forged_marker_is_refused(tmp_path):
    (tmp_path / RUN_MARKER).write_text("{not json")
    with pytest.raises(ZendarError, match="cannot be read"):
        RunDirectory(tmp_path, {"config": "tiny"})


def test_steps_are_reused_with_the_same_inputs_and_redone_with_others(tmp_path):
    run = RunDirectory(tmp_path, {"config": "tiny"})
    calls = []

    def compute(step_dir):
        calls.append(step_dir)
        (step_dir / "out.txt").write_text(str(len(calls)))

    first = run.step("split", {"seed": 0}, compute)
    again = RunDirectory(tmp_path, {"config": "tiny"}).step("split", {"seed": 0}, compute)
    assert first[2] is False and again[2] is True and again[1] == first[1] and len(calls) == 1
    changed = run.step("split", {"seed": 1}, compute)
    assert changed[2] is False and changed[1] != first[1] and (tmp_path / "split" / "out.txt").read_text() == "2"


def test_an_interrupted_step_keeps_its_partial_files_for_the_rerun(tmp_path):
    run = RunDirectory(tmp_path, {"config": "tiny"})

    def interrupted(step_dir):
        (step_dir / "epoch-1.pt").write_text("partial")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run.step("train", {"seed": 0}, interrupted)
    seen = []
    run.step("train", {"seed": 0}, lambda d: seen.append((d / "epoch-1.pt").read_text()))
    assert seen == ["partial"]
