"""``zendar-data synth`` picks one process where worker processes cannot pay off."""

import pytest

from zendar_dataset.cli import data as data_cli
from zendar_dataset.cli.data_synth import default_jobs
from zendar_dataset.sim import generate


@pytest.mark.parametrize(
    ("cpus", "scenes", "expected"),
    [
        (2, 3, 1),  # tiny's default: spawning 2 workers cost more than it saved
        (2, 4, 2),
        (2, 5, 2),  # demo's default
        (2, 12, 2),
        (8, 5, 1),
        (8, 16, 8),
        (1, 5, 1),
    ],
)
def test_default_jobs(monkeypatch, cpus, scenes, expected):
    monkeypatch.setattr(generate, "usable_cpus", lambda: cpus)
    assert default_jobs(scenes) == expected


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--profile", "tiny"], 1),
        (["--profile", "tiny", "--scenes", "12"], 2),
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
