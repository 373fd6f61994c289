"""``zendar-data synth`` picks one process where worker processes cannot pay off."""

import pytest

from zendar_dataset.cli import data as data_cli
from zendar_dataset.cli.data_synth import default_jobs
from zendar_dataset.sim import generate


@pytest.mark.parametrize(
    ("cpus", "profile", "scenes", "expected"),
    [
        (2, "tiny", 3, 1),  # seconds-long scenes: spawning workers costs more than it saves
        (2, "tiny", 40, 1),
        (2, "demo", 5, 2),  # 5 scenes >= 2 x 2 workers
        (2, "demo", 3, 1),  # a second round would leave a worker idle most of the run
        (2, "paper", 27, 2),
        (8, "demo", 5, 1),
        (8, "paper", 27, 8),
        (1, "demo", 5, 1),
    ],
)
def test_default_jobs(monkeypatch, cpus, profile, scenes, expected):
    monkeypatch.setattr(generate, "usable_cpus", lambda: cpus)
    assert default_jobs(profile, scenes) == expected


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--profile", "tiny"], 1),
        (["--profile", "demo"], 2),
        (["--profile", "demo", "--scenes", "3"], 1),
        (["--profile", "tiny", "--jobs", "2"], 2),  # an explicit --jobs is kept
    ],
)
def test_cli_passes_its_choice(monkeypatch, tmp_path, argv, expected):
    calls = []
    monkeypatch.setattr(generate, "usable_cpus", lambda: 2)
    monkeypatch.setattr(generate, "synthesize_dataset", lambda out, **kwargs: calls.append(kwargs) or out)
    assert data_cli.main(["synth", str(tmp_path / "out"), "--quiet", *argv]) == 0
    assert [c["jobs"] for c in calls] == [expected]
