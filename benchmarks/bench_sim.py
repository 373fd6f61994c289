"""Simulator costs: cube synthesis (fast vs exact), SAR image, lidar sweep, whole tiny/demo datasets.

The whole-dataset rows compare ``jobs`` worker processes (the usable CPUs) with
``jobs=1`` (scenes one after another in this process), measured in the same run;
both write byte-identical datasets. The crossover rows time ``tiny`` datasets of
several sizes both ways, interleaved: what ``zendar-data synth``'s choice of
``--jobs`` (``default_jobs``) rests on.

Run: python benchmarks/bench_sim.py [--skip-demo] [--skip-serial-demo] [--crossover 3 6 12]
(the demo rows take minutes; the figure quoted in docs/simulator.md is
``time zendar-data synth /tmp/demo_jobs --profile demo`` on an idle 2-core machine).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import pathlib
import shutil
import tempfile
import time

import numpy as np
from harness import Spread, interleaved, print_environment, print_load_after

from zendar_dataset.cli.data_synth import default_jobs
from zendar_dataset.geometry.poses import PoseInterpolator
from zendar_dataset.radar.fmcw import beat_signal_exact
from zendar_dataset.radar.range_doppler import range_doppler
from zendar_dataset.sim import ego as ego_model
from zendar_dataset.sim.generate import synthesize_dataset, usable_cpus
from zendar_dataset.sim.imperfections import Imperfections
from zendar_dataset.sim.lidar import lidar_sweep
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sim.radar_model import synthesize_cube
from zendar_dataset.sim.sar_formation import pulse_spacing_m, sar_waveform
from zendar_dataset.sim.scene import build_scene, simulate_cube, simulate_sar, stream_rng


def _timed(fn, repeats):
    """(median seconds, min / median / max, last result) of ``repeats`` calls."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    spread = Spread.of(times)
    return spread.median, spread, result


def bench_cube() -> None:
    params = ego_model.radar_params(get_profile("paper"))
    rng = np.random.default_rng(0)
    r = rng.uniform(5.0, 80.0, 20)
    az = rng.uniform(-1.0, 1.0, 20)
    pos = np.stack([r * np.cos(az), r * np.sin(az), rng.uniform(-0.3, 0.3, 20)], axis=1)
    vel = np.concatenate([rng.uniform(-12, 12, (20, 2)), np.zeros((20, 1))], axis=1)
    amp = rng.normal(size=20) + 1j * rng.normal(size=20)
    t = np.arange(params.n_chirps) * params.chirp_interval_s
    per_chirp = pos[:, None] + vel[:, None] * t[None, :, None]
    exact_s, _, exact = _timed(lambda: range_doppler(beat_signal_exact(params, pos, vel, amp)), 2)
    print("cube synthesis, 512 x 256 x 4, 20 moving targets (medians; fast: min-max of 7)")
    print(f"{'half-width (bins)':>18} {'fast ms':>22} {'exact ms':>9} {'speed-up':>9} {'rel. L2 err':>12}")
    for half_width in (4, 6, 8):
        fast_s, spread, fast = _timed(lambda: synthesize_cube(params, per_chirp, amp, half_width_bins=half_width), 7)
        error = np.linalg.norm(fast - exact) / np.linalg.norm(exact)
        print(f"{half_width:>18} {spread.scaled(1e3).text('.1f'):>22} {exact_s * 1e3:9.1f} {exact_s / fast_s:9.1f} "
              f"{error:12.2e}")


def bench_scene_parts() -> None:
    print("\nper-frame costs in a simulated scene")
    print(f"{'profile':>8} {'SAR image ms':>13} {'lidar sweep ms':>15} {'scatterers':>11}")
    for name in ("tiny", "demo"):
        profile = get_profile(name)
        truth = build_scene(profile, 0, 0)
        written = truth.tracklog_written
        tracklog = PoseInterpolator(written.timestamp_ns, written.position_ecef, written.attitude_wxyz)
        rng = stream_rng(0, 0, "sar_front_left")
        sar_s, _, _ = _timed(lambda: simulate_sar(truth, profile, "front_left", 0.55, rng, tracklog), 3)
        rotation, position = ego_model.sensor_poses_enu(truth.ego, ego_model.LIDAR, np.array(0.55))
        boxes = truth.world.boxes_at(0.55)
        lidar_s, _, _ = _timed(lambda: lidar_sweep(rng, rotation, position, boxes, profile.lidar_azimuth_step_deg), 3)
        print(f"{name:>8} {sar_s * 1e3:13.1f} {lidar_s * 1e3:15.1f} {truth.world.static_scatterers.rcs_m2.size:11d}")
    paper = get_profile("paper")
    beams = 16 * int(360 / paper.lidar_azimuth_step_deg)
    truth = build_scene(get_profile("demo"), 0, 0)
    rotation, position = ego_model.sensor_poses_enu(truth.ego, ego_model.LIDAR, np.array(0.55))
    rng = np.random.default_rng(0)
    lidar_s, _, _ = _timed(lambda: lidar_sweep(rng, rotation, position, truth.world.boxes_at(0.55), paper.lidar_azimuth_step_deg), 3)
    print(f"paper-resolution VLP-16 sweep ({beams} firings): {lidar_s * 1e3:.1f} ms")


def bench_frames(names: tuple[str, ...]) -> None:
    """Per-frame cube and SAR costs with every imperfection on (the profiles) and off, in the same run,
    and the time a full scene of each profile would take at those costs (both radars, cubes and SAR)."""
    print("\nper-frame costs, imperfections on / off (same run), and the projected scene (2 radars, cubes + SAR)")
    print(f"{'profile':>8} {'SAR pixels':>11} {'pulses':>7} {'cube s on':>10} {'cube s off':>11} {'SAR s on':>9} "
          f"{'SAR s off':>10} {'scene min':>10}")
    for name in names:
        profile = get_profile(name)
        off = dataclasses.replace(profile, imperfections=Imperfections.none())
        truth_on, truth_off = build_scene(profile, 0, 0), build_scene(off, 0, 0)
        written = truth_on.tracklog_written
        tracklog = PoseInterpolator(written.timestamp_ns, written.position_ecef, written.attitude_wxyz)
        repeats = 1 if name == "paper" else 3
        costs = {}
        for label, prof, truth in (("on", profile, truth_on), ("off", off, truth_off)):
            rng = stream_rng(0, 0, "front_left")
            costs[f"cube {label}"], _, _ = _timed(lambda: simulate_cube(truth, prof, "front_left", 0.55, rng), repeats)
            costs[f"sar {label}"], _, image = _timed(
                lambda: simulate_sar(truth, prof, "front_left", 0.55, rng, tracklog), repeats)
        waveform = sar_waveform(ego_model.radar_params(profile), profile.sar_bandwidth_hz, profile.sar_coverage_m)
        pulses = int(profile.sar_aperture_m / pulse_spacing_m(waveform)) + 1
        frames = profile.scene_duration_s * profile.radar_rate_hz * len(ego_model.RADARS)
        scene_min = frames * (costs["cube on"] + costs["sar on"]) / 60
        print(f"{name:>8} {image[0].size:11d} {pulses:7d} {costs['cube on']:10.2f} {costs['cube off']:11.2f} "
              f"{costs['sar on']:9.2f} {costs['sar off']:10.2f} {scene_min:10.1f}")


def bench_dataset(name: str, jobs: int, serial_s: float | None) -> float:
    """Write the profile's default dataset with ``jobs`` workers; print a row; return the seconds."""
    profile = get_profile(name)
    out = pathlib.Path(tempfile.mkdtemp()) / name
    start = time.perf_counter()
    synthesize_dataset(out, name, progress=False, jobs=jobs)
    seconds = time.perf_counter() - start
    size = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    ratio = f"{serial_s / seconds:9.2f}" if serial_s is not None else f"{'-':>9}"
    print(f"{name:>8} {profile.default_scenes:7d} {jobs:5d} {seconds:10.1f} {ratio} {size / 2**20:10.1f}")
    shutil.rmtree(out.parent)
    return seconds


def bench_crossover(scene_counts: list[int], repeats: int) -> None:
    """``tiny`` scenes, ``jobs=1`` against the usable CPUs, interleaved: where workers start to pay off."""
    cpus = usable_cpus()
    print(f"\ntiny profile, jobs 1 vs {cpus} by number of scenes ({repeats} interleaved runs each; "
          f"'zendar-data synth' picks jobs {default_jobs(3)} for the default 3)")
    print(f"{'scenes':>7} {'jobs 1 s':>22} {f'jobs {cpus} s':>22} {'speed-up':>9}")
    for scenes in scene_counts:
        def run(jobs: int) -> None:
            out = pathlib.Path(tempfile.mkdtemp()) / "tiny"
            synthesize_dataset(out, "tiny", n_scenes=scenes, progress=False, jobs=jobs)
            shutil.rmtree(out.parent)

        times = interleaved({1: lambda: run(1), cpus: lambda: run(cpus)}, repeats, warmup=0)
        print(f"{scenes:>7} {times[1].text('.1f'):>22} {times[cpus].text('.1f'):>22} "
              f"{times[1].median / times[cpus].median:>9.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--skip-demo", action="store_true", help="skip the demo dataset (minutes)")
    parser.add_argument("--skip-serial-demo", action="store_true", help="skip the jobs=1 demo reference (minutes)")
    parser.add_argument("--crossover", type=int, nargs="*", default=[3, 6, 12], metavar="SCENES",
                        help="tiny-profile scene counts for the jobs 1 vs all-CPUs comparison (none: skip)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per crossover point")
    parser.add_argument("--paper", action="store_true", help="add the paper profile's per-frame costs (minutes)")
    parser.add_argument("--frames-only", action="store_true", help="only the per-frame costs")
    args = parser.parse_args()
    if args.frames_only:
        print_environment(("numpy", "numba", "scipy"))
        bench_frames(("tiny", "demo", "paper") if args.paper else ("tiny", "demo"))
        print_load_after()
        return
    print_environment(("numpy", "numba", "scipy"))
    bench_cube()
    bench_scene_parts()
    bench_frames(("tiny", "demo", "paper") if args.paper else ("tiny", "demo"))
    cpus = usable_cpus()
    print(f"\nwhole default datasets ({cpus} usable CPUs, load average before {os.getloadavg()[0]:.1f})")
    print(f"{'profile':>8} {'scenes':>7} {'jobs':>5} {'seconds':>10} {'speed-up':>9} {'MiB':>10}")
    serial = bench_dataset("tiny", 1, None)
    bench_dataset("tiny", cpus, serial)
    if not args.skip_demo:
        serial = None if args.skip_serial_demo else bench_dataset("demo", 1, None)
        bench_dataset("demo", cpus, serial)
    if args.crossover:
        bench_crossover(args.crossover, args.repeats)
    print_load_after()


if __name__ == "__main__":
    main()
