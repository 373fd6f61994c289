"""Measurement: the SAR static-scene test's window (``SarTestParams.search_radius_m``) and threshold.

Two tables on a dataset's training split, for each window radius:

1. the CFAR chain fitted on every training scene (``zendar_baselines.classical.chain_fit.fit_chain_params``,
   as ``zendar-bench fit-chain ROOT --split train`` with that window): the fitted threshold, the SAR
   value's ROC AUC of on-car against other CFAR points per band, on the fitting frames and on the
   validation scenes, and the chain's AP on both;
2. the automatic labels at each threshold (``zendar-bench autolabels ROOT --out DIR --threshold-db T``
   with that window): object precision and recall per band against the CFAR-gated manual-label masks,
   and the worst band's object F1 (the criterion of ``DEFAULT_THRESHOLD_DB``).

Neither table reads the test split. The figures of docs/baselines.md ("The SAR reading's window") come
from the default bench's dataset, the cached ``demo-short`` 60 scenes that ``zendar-bench`` simulates.

Run: python benchmarks/sar_window_sweep.py ROOT [--radii 0.5,0.3,0.2,0] [--thresholds 12,14,16,17,18,19,20]
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

from harness import print_environment

from zendar_baselines.bench.autolabels import write_auto_labels
from zendar_baselines.classical.chain_fit import fit_chain_params
from zendar_baselines.fingerprints import dataset_index
from zendar_baselines.labels.masks import MaskParams
from zendar_dataset.detection import ChainParams
from zendar_dataset.eval.protocol import RANGE_BANDS


def _numbers(text: str) -> list[float]:
    return [float(value) for value in text.split(",")]


def _bands(values: dict, scale: float = 1.0, digits: int = 3) -> str:
    return " / ".join("—" if values.get(band) is None else f"{scale * values[band]:.{digits}f}" for band in RANGE_BANDS)


def chain_table(root: str, radii: list[float]) -> None:
    print("| window | fitted threshold | AUC fit near / mid / far | AUC val | AP fit near / mid / far / all | AP val |")
    print("|---|---:|---|---|---|---|")
    for radius_m in radii:
        base = ChainParams()
        base = replace(base, sar=replace(base.sar, search_radius_m=radius_m))
        params, summary = fit_chain_params(root, "train", base=base, progress=False)
        check = summary["check"]
        fit_ap, check_ap = (" / ".join(f"{100 * ap[band]:.1f}" for band in (*RANGE_BANDS, "all")) for ap in (summary["ap"], check["ap"]))
        print(f"| {radius_m:g} m | {params.sar.threshold_db:.1f} dB | {_bands(summary['point_separation']['auc_per_band'])} "
              f"| {_bands(check['auc_per_band'])} | {fit_ap} | {check_ap} |", flush=True)


def label_table(root: str, radii: list[float], thresholds: list[float]) -> None:
    index = dataset_index(root)
    scenes = index.scene_ids("train")
    print("| window | threshold | object precision near / mid / far | object recall near / mid / far | worst-band F1 |")
    print("|---|---:|---|---|---:|")
    with tempfile.TemporaryDirectory(prefix="sar-window-") as scratch:
        for radius_m in radii:
            for threshold_db in thresholds:
                base = MaskParams()
                params = replace(base, chain=replace(base.chain, sar=replace(
                    base.chain.sar, threshold_db=threshold_db, search_radius_m=radius_m)))
                out = Path(scratch) / f"r{radius_m:g}-t{threshold_db:g}"
                bands = write_auto_labels(index, scenes, out, params=params)["quality"]["bands"]
                precision = {b: bands[b]["object_precision"] for b in RANGE_BANDS}
                recall = {b: bands[b]["object_recall"] for b in RANGE_BANDS}
                f1 = min(2 * precision[b] * recall[b] / (precision[b] + recall[b]) if precision[b] + recall[b] else 0.0
                         for b in RANGE_BANDS)
                print(f"| {radius_m:g} m | {threshold_db:g} dB | {_bands(precision, 100, 1)} % | {_bands(recall, 100, 1)} % "
                      f"| {100 * f1:.1f} % |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("root", help="a dataset root with labelled training and validation scenes")
    parser.add_argument("--radii", type=_numbers, default=[0.5, 0.3, 0.2, 0.0], help="window radii, metres")
    parser.add_argument("--thresholds", type=_numbers, default=[12.0, 14.0, 16.0, 17.0, 18.0, 19.0, 20.0],
                        help="the automatic labels' thresholds, dB")
    parser.add_argument("--no-labels", action="store_true", help="only the chain table")
    args = parser.parse_args()
    print_environment(("numpy", "scipy", "scikit-learn"))
    chain_table(args.root, args.radii)
    if not args.no_labels:
        print()
        label_table(args.root, args.radii, args.thresholds)


if __name__ == "__main__":
    main()
