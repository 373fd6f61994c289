"""``zendar-data info ROOT``: scenes per split, streams with counts, durations and rates,
and synchronisation residuals of every stream against the SAR reference."""

from __future__ import annotations

import argparse

import numpy as np

from zendar_dataset.cli.arguments import number_between
from zendar_dataset.cli.common import EXIT_OK

ALL_GROUPS = ("radar", "sar", "camera", "lidar", "tracklog", "labels")
#: Largest ``--tolerance-ms``: one day, far beyond any scene, so every larger value would match the same.
MAX_TOLERANCE_MS = 86_400_000


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "info",
        help="summarise a dataset: scenes, streams, rates, sync residuals",
        description="Print scenes per split, every stream's element count, duration and rate, and the "
        "synchronisation residuals (median and max |dt|, misses and drops) of every stream against each "
        "scene's first SAR stream, with the loader's default tolerances. Reads metadata and timestamps only.",
    )
    parser.add_argument("root", metavar="ROOT", help="dataset root (directory or fsspec URL)")
    parser.add_argument("--split", help="only this split (default: all)")
    parser.add_argument(
        "--tolerance-ms",
        type=number_between("--tolerance-ms", 0, MAX_TOLERANCE_MS),
        default=None,
        help=f"one matching tolerance for every stream, 0 to {MAX_TOLERANCE_MS:,} ms (one day; default: per stream)",
    )
    parser.set_defaults(func=run)


def _stream_rows(reader) -> list[tuple[str, int, float, float]]:
    rows = []
    for stream in reader.streams:
        if stream == "labels/moving_cars":
            times = reader.timestamps(stream)
            frames = np.unique(times).size
            rows.append((stream, int(times.size), float("nan"), float("nan"), f"{frames} labelled frames"))
            continue
        times = reader.timestamps(stream)
        duration_s = (times[-1] - times[0]) / 1e9 if times.size > 1 else 0.0
        rate_hz = 1e9 / float(np.median(np.diff(times))) if times.size > 1 else float("nan")
        rows.append((stream, int(times.size), duration_s, rate_hz, ""))
    return rows


def _scene_has(reader, group: str) -> bool:
    if group == "tracklog":
        return "tracklog" in reader.streams
    if group == "labels":
        return "labels/moving_cars" in reader.streams
    return bool(reader.sensors(group))


def _ms(value) -> str:
    try:
        ms = float(value) / 1e6
    except (TypeError, ValueError):
        return "-"
    return "-" if np.isnan(ms) else f"{ms:.3f}"


def describe_scene(reader, tolerance_ms: float | None) -> list[str]:
    from zendar_dataset.sync import scene_sync_table

    lines = [f"  scene {reader.scene_id} ({reader.backend})"]
    lines.append(f"    {'stream':<22}{'count':>8}{'duration_s':>12}{'rate_hz':>10}")
    for stream, count, duration_s, rate_hz, note in _stream_rows(reader):
        duration = "-" if np.isnan(duration_s) else f"{duration_s:.3f}"
        rate = "-" if np.isnan(rate_hz) else f"{rate_hz:.2f}"
        lines.append(f"    {stream:<22}{count:>8}{duration:>12}{rate:>10}  {note}".rstrip())
    if not reader.sensors("sar"):
        lines.append("    sync: no SAR stream, so no reference frames")
        return lines
    present = [g for g in ALL_GROUPS if _scene_has(reader, g)]
    table = scene_sync_table(reader, present, reference="sar", tolerance_ms=tolerance_ms)
    stats = table.residual_stats()
    lines.append(f"    sync vs {table.reference} ({table.n_reference} frames, dt = element - reference):")
    lines.append(
        f"    {'stream':<22}{'tol_ms':>8}{'matched':>9}{'missing':>9}{'dropped':>9}"
        f"{'median|dt|_ms':>15}{'max|dt|_ms':>12}"
    )
    for row in stats.itertuples(index=False):
        if row.stream == table.reference:
            continue
        tol = "interp" if np.isnan(row.tolerance_ms) else f"{row.tolerance_ms:.1f}"
        lines.append(
            f"    {row.stream:<22}{tol:>8}{row.matched:>9}{row.missing:>9}{row.dropped:>9}"
            f"{_ms(row.abs_dt_median_ns):>15}{_ms(row.abs_dt_max_ns):>12}"
        )
    return lines


def run(args: argparse.Namespace) -> int:
    from zendar_dataset.format import open_dataset

    index = open_dataset(args.root)
    splits = [args.split] if args.split else list(index.splits)
    if args.split:
        index.scene_ids(args.split)  # unknown split -> ZendarFormatError (exit 2)
    print(f"dataset {index.name!r} at {args.root}: {len(index.scenes)} scenes")
    for split in splits:
        scene_ids = index.scene_ids(split)
        print(f"split {split}: {len(scene_ids)} scenes")
        for scene_id in scene_ids:
            reader = index.open_scene(scene_id)
            try:
                print("\n".join(describe_scene(reader, args.tolerance_ms)))
            finally:
                reader.close()
    return EXIT_OK
