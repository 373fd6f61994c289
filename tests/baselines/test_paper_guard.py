"""The paper configuration on one CPU machine is refused before anything is written, with its
projected time, unless a cluster, a GPU or --allow-slow is given."""

from __future__ import annotations

import re

import pytest

from tests.baselines.test_bench_cli import bench
from zendar_baselines.bench.configs import get_config
from zendar_baselines.bench.paper_guard import check_paper_config_fits
from zendar_dataset.errors import ZendarError


def _projected_hours(message: str) -> tuple[float, float]:
    simulation = re.search(r"projects to ~([\d,]+) h", message)
    training = re.search(r"more than ([\d,]+) h", message)
    return float(simulation.group(1).replace(",", "")), float(training.group(1).replace(",", ""))


def test_the_refusal_projects_the_simulation_over_the_usable_cpus():
    paper = get_config("paper")
    with pytest.raises(ZendarError) as two:
        check_paper_config_fits(paper, "cpu", None, False, cpus=2)
    with pytest.raises(ZendarError) as eight:
        check_paper_config_fits(paper, "cpu", None, False, cpus=8)
    simulation_2, training_2 = _projected_hours(str(two.value))
    simulation_8, training_8 = _projected_hours(str(eight.value))
    # 27 scenes of 30 s at ~10 core-hours each.
    assert simulation_2 == pytest.approx(27 * 10 / 2, rel=0.01) and simulation_8 == pytest.approx(simulation_2 / 4, rel=0.01)
    assert training_2 == training_8 > 600
    for hint in ("--scheduler", "--device cuda", "--allow-slow"):
        assert hint in str(two.value)


@pytest.mark.parametrize("config, device, scheduler, allow_slow", [
    ("paper", "cuda", None, False), ("paper", "cpu", "tcp://127.0.0.1:8786", False), ("paper", "cpu", None, True),
    ("demo", "cpu", None, False), ("gpu", "cpu", None, False), ("tiny", "cpu", None, False),
])
def test_a_cluster_a_gpu_insistence_or_another_config_passes(config, device, scheduler, allow_slow):
    check_paper_config_fits(get_config(config), device, scheduler, allow_slow, cpus=2)


def test_zendar_bench_refuses_the_paper_config_here_and_writes_nothing(tmp_path):
    done = bench("--config", "paper", "--out", str(tmp_path / "out"), env_home=tmp_path, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "the paper configuration does not fit one CPU machine" in done.stderr and "--allow-slow" in done.stderr
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()
