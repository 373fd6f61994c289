"""The paper configuration on one CPU machine: refused before anything is written unless the user
insists, with the projected time in the message."""

from __future__ import annotations

from zendar_dataset.errors import ZendarError
from zendar_dataset.sim.profiles import get_profile

from zendar_baselines.bench.configs import BenchConfig

#: Core-hours to simulate one 30 s ``paper`` scene, measured: a 5 s scene took 36 min 20 s on 2 AVX2
#: cores (≈ 3.6 h per 30 s), and the SAR fidelity changes since make a paper image 1.45 times longer
#: (docs/simulator.md, "Costs"): ≈ 5 h on 2 cores.
PAPER_SCENE_CORE_HOURS_PER_30_S = 10.0
#: Training work of the paper config at its epoch ceilings, 3 seeds of the 6 CNN rows, counted with
#: ``benchmarks/bench_paper_projection.py``: 6.3 h at a sustained 100 TFLOP/s.
PAPER_TRAINING_FLOP = 6.3 * 3600 * 100e12
#: A generous bound on a CPU machine's training throughput (a 2-core AVX-512 CPU peaks near 0.4
#: TFLOP/s in float32): the training time printed is a lower bound.
CPU_TRAINING_FLOPS = 1e12


def check_paper_config_fits(config: BenchConfig, device: str, scheduler: str | None, allow_slow: bool, cpus: int) -> None:
    """Raise ZendarError for the ``paper`` config on this machine's CPUs alone (no ``--scheduler``, no
    ``--device cuda``) unless ``allow_slow``; the message gives the projected simulation and training time.
    """
    if config.name != "paper" or device != "cpu" or scheduler is not None or allow_slow:
        return
    profile = get_profile(config.sim_profile)
    simulation_h = config.n_scenes * profile.scene_duration_s / 30.0 * PAPER_SCENE_CORE_HOURS_PER_30_S / max(1, cpus)
    training_h = PAPER_TRAINING_FLOP / CPU_TRAINING_FLOPS / 3600
    raise ZendarError(
        f"the paper configuration does not fit one CPU machine: simulating its {config.n_scenes} scenes of "
        f"{profile.scene_duration_s:g} s projects to ~{simulation_h:,.0f} h on this machine's {cpus} usable CPU(s) "
        f"(~{PAPER_SCENE_CORE_HOURS_PER_30_S:g} core-hours per 30 s scene, measured), and training its 6 CNN rows to "
        f"more than {training_h:,.0f} h on CPUs ({PAPER_TRAINING_FLOP:.1e} FLOP counted, at a generous 1 TFLOP/s; "
        "~6.3 h on one GPU at 100 TFLOP/s). Simulate on a cluster with --scheduler ADDRESS (docs/cluster.md), "
        "train with --device cuda, or pass --allow-slow to run here anyway")


__all__ = ["check_paper_config_fits"]
