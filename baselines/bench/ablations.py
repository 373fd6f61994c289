"""``zendar-bench --ablations``: what four of the chain's changes moved, and what optional input
channels add, measured as rows beside Table 1.

- ``sar-reading-alone``: the CFAR row with the SAR test as it was before the range-Doppler SNR was
  subtracted (a point's SAR value is its SAR reading alone, dB over the image median:
  :attr:`zendar_dataset.detection.SarTestParams.subtract_rd_snr` False), its threshold, radius and
  offset fitted the same way on the same labelled frames. Reference: the CFAR row.
- ``no-radar-shadow``: the CFAR row with the SAR test judging points in the radar's shadow like any
  other (:attr:`zendar_dataset.detection.SarTestParams.shadow_margin_m` None; the shadow is measured
  by the lidar, :mod:`zendar_dataset.sar.shadow`): the paper's test, which calls the multipath ghosts
  behind facades dynamic. Fitted the same way. Reference: the CFAR row.
- ``sar-window-0.5m``: the CFAR row with a point's SAR reading taken as the brightest pixel within
  0.5 m of its projection (the window before 3 December) instead of
  :data:`zendar_dataset.sar.frames.SAR_SEARCH_RADIUS_M`. Fitted the same way. Reference: the CFAR row.
- ``cfar-gated-targets``: :data:`ABLATION_MODEL` supervised-only, trained on the manual-label targets
  as they were before the box projection (MOVING only at CFAR peaks inside a labelled box and their
  grown segments: ``MaskParams(manual_targets="cfar-peaks")``), its checkpoints chosen on validation
  masks made the same way; otherwise the row's own training, chain fit and scoring, with the same
  seeds. Reference: that architecture's supervised-only row.
- ``phase-difference-channels`` and ``static-doppler-channel``: :data:`ABLATION_MODEL` supervised-only
  with optional channels beside each map's log power (:mod:`zendar_baselines.cnn.input_channels`):
  the phase between neighbouring antennas (the angle the paper's input drops), or every cell's
  Doppler-test residual (its radial velocity against a static point's at its azimuth, given the
  ego's motion). The row's own targets, validation masks, seeds, schedule, chain fit and scoring;
  only the input changes. Reference: that architecture's supervised-only row.

Each ablation row is scored on the test split as Table 1's rows are and compared with its reference
by the claims' paired bootstrap (every seed, the same resamples of the test split's time blocks and
the same seed draws, :func:`zendar_baselines.bench.claims.shared_resamples`): the difference ablation − reference per
band with its 95 % interval; "higher" / "lower" when the interval excludes 0, else "no difference
shown". Outputs: ``ablations.md`` and ``results.json``'s ``ablations``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from zendar_dataset.detection import ChainParams, SarTestParams
from zendar_dataset.eval.evaluate import MatchedDetections
from zendar_dataset.eval.paired import FAILS, HOLDS, paired_difference
from zendar_dataset.eval.protocol import RANGE_BANDS
from zendar_dataset.eval.report import read_metrics

from zendar_baselines.bench.context import RowSeed, RunContext, TrainingLabels
from zendar_baselines.bench.results_table import METHOD_NAMES, Row
from zendar_baselines.bench.run_directory import RunDirectory
from zendar_baselines.cnn.input_channels import InputChannels
from zendar_baselines.labels.masks import MaskParams

#: The architecture whose supervised-only row the target ablation retrains (the paper's first CNN row).
ABLATION_MODEL = "fpn-resnet34"
#: The input-channel ablations: name -> (channels beside the log power, what the row changes).
INPUT_CHANNEL_ABLATIONS = {
    "phase-difference-channels": (
        InputChannels(phase_differences=True),
        "input: + cos and sin of the phase between neighbouring antennas (6 channels per map)"),
    "static-doppler-channel": (
        InputChannels(static_doppler=True),
        "input: + the Doppler test's residual of every cell (1 channel per map)"),
}
#: The CFAR row's ablations of the SAR test: name, the test's settings, the detector's name in the
#: fit, what the row changes.
CFAR_SAR_TEST_ABLATIONS = (
    ("sar-reading-alone", replace(SarTestParams(), subtract_rd_snr=False), "CFAR (SAR reading alone)",
     "SAR test: the SAR reading alone (no range-Doppler SNR subtracted)"),
    ("no-radar-shadow", replace(SarTestParams(), shadow_margin_m=None), "CFAR (no radar shadow)",
     "SAR test: points in the radar's shadow behind lidar obstacles judged like any other (the paper's test)"),
    ("sar-window-0.5m", replace(SarTestParams(), search_radius_m=0.5), "CFAR (0.5 m SAR window)",
     "SAR test: a point's SAR reading the brightest pixel within 0.5 m of it (the window before 3 December), not 0.2 m"),
)
#: Where the ablations' steps live in the run directory.
ABLATIONS_DIR = "ablations"
#: What a comparison's interval says, by the paired verdict of ablation − reference.
READINGS = {HOLDS: "higher", FAILS: "lower"}
NO_DIFFERENCE = "no difference shown"


@dataclass(frozen=True)
class Ablation:
    """One ablation row: what it changes, the Table 1 row it is compared with, and where its first
    seed's outputs are (``folder``, relative to the run directory: ``.../seed-0`` for a CNN row)."""

    name: str
    change: str
    reference: str
    row: Row
    folder: str

    def seed_folders(self) -> list[str]:
        """Every seed's outputs folder, in seed order (one for a CFAR row), relative to the run directory."""
        parent, name = self.folder.rpartition("/")[::2]
        if not name.startswith("seed-"):
            return [self.folder]
        return [f"{parent}/seed-{k}" for k in range(len(self.row.seed_metrics))]

    def to_json(self) -> dict[str, Any]:
        """The row's JSON, with its first seed's ``metrics`` and ``predictions`` paths and every seed's
        (``seed_outputs``: what the paired differences pool)."""
        return self.row.to_json() | {
            "metrics": f"{self.folder}/metrics.json", "predictions": f"{self.folder}/predictions.json",
            "seed_outputs": [{"metrics": f"{folder}/metrics.json", "predictions": f"{folder}/predictions.json"}
                             for folder in self.seed_folders()],
        }


def run_ablations(run: RunDirectory, context: RunContext, labels: TrainingLabels, keys: dict[str, str], seeds: int,
                  jobs: int | None) -> list[Ablation]:
    """Every ablation's steps (cached like the run's own) and its rows.

    Parameters
    ----------
    run, context, labels
        The run's directory, context and training labels.
    keys
        The run's ``split``, ``autolabels``, ``label_masks`` and ``validation_masks`` step keys.
    seeds
        Seeds of the retrained row (those of Table 1's rows).
    jobs
        ``--jobs`` (:func:`zendar_baselines.bench.run.seed_jobs`).
    """
    from zendar_baselines.bench import steps
    from zendar_baselines.bench.run import SeedStep, run_seed_steps, seed_jobs

    base_inputs = context.step_inputs()
    ablations = []

    # The SAR test as it was before two of its changes, on the CFAR row.
    for name, sar, detector, change in CFAR_SAR_TEST_ABLATIONS:
        ablations.append(_cfar_ablation(run, context, labels, keys, name, replace(ChainParams(), sar=sar), detector, change))

    # CFAR-gated manual-label targets, on the supervised-only row.
    name = "cfar-gated-targets"
    gated = MaskParams(manual_targets="cfar-peaks")
    masks_dir, masks_key, _ = run.step(
        f"{ABLATIONS_DIR}/{name}/label_masks", {**base_inputs, "split": keys["split"], "ablation": name},
        lambda d: steps.write_label_masks(context, labels.split, d, gated))
    validation_dir, validation_key, _ = run.step(
        f"{ABLATIONS_DIR}/{name}/validation_masks", {**base_inputs, "ablation": name},
        lambda d: steps.write_validation_masks(context, d, gated))
    gated_labels = replace(labels, masks_dir=masks_dir, validation_dir=validation_dir)
    seed_steps = [
        SeedStep(context, run.identity, gated_labels, RowSeed(ABLATION_MODEL, False, seed),
                 {**base_inputs, "split": keys["split"], "autolabels": keys["autolabels"], "label_masks": masks_key,
                  "validation_masks": validation_key, "model": ABLATION_MODEL, "pretrained": False, "seed": seed,
                  "ablation": name},
                 f"{ABLATIONS_DIR}/{name}")
        for seed in range(seeds)
    ]
    run_seed_steps(run, seed_steps, seed_jobs(jobs, len(seed_steps), context.device))
    reference = RowSeed(ABLATION_MODEL, False, 0).row_key
    ablations.append(Ablation(
        name, "manual-label targets: CFAR peaks inside labelled boxes (before the box projection)", reference,
        Row(f"{reference}-{name}", METHOD_NAMES[ABLATION_MODEL], False, True,
            [read_metrics(run.path / step.name / "metrics.json") for step in seed_steps]),
        seed_steps[0].name))

    # Optional input channels, on the supervised-only row: the same targets, seeds and training.
    channel_steps = {
        name: [
            SeedStep(context, run.identity, labels, RowSeed(ABLATION_MODEL, False, seed, channels),
                     {**base_inputs, "split": keys["split"], "autolabels": keys["autolabels"],
                      "label_masks": keys["label_masks"], "validation_masks": keys["validation_masks"],
                      "model": ABLATION_MODEL, "pretrained": False, "seed": seed, "ablation": name,
                      "inputs": channels.name},
                     f"{ABLATIONS_DIR}/{name}")
            for seed in range(seeds)
        ]
        for name, (channels, _) in INPUT_CHANNEL_ABLATIONS.items()
    }
    every_step = [step for named in channel_steps.values() for step in named]
    run_seed_steps(run, every_step, seed_jobs(jobs, len(every_step), context.device))
    for name, (_, change) in INPUT_CHANNEL_ABLATIONS.items():
        named = channel_steps[name]
        ablations.append(Ablation(
            name, change, reference,
            Row(f"{reference}-{name}", METHOD_NAMES[ABLATION_MODEL], False, True,
                [read_metrics(run.path / step.name / "metrics.json") for step in named]),
            named[0].name))
    return ablations


def _cfar_ablation(run: RunDirectory, context: RunContext, labels: TrainingLabels, keys: dict[str, str], name: str,
                   base: ChainParams, detector: str, change: str) -> Ablation:
    """The CFAR row with the chain's settings ``base``: its constants fitted the same way on the same
    labelled frames, its predictions scored on the test split."""
    from zendar_baselines.bench import chain_step, scoring
    from zendar_baselines.classical.chain_fit import cfar_cells_for

    base_inputs = context.step_inputs()
    fit_dir, fit_key, _ = run.step(
        f"{ABLATIONS_DIR}/{name}/chain_fit", {**base_inputs, "split": keys["split"], "ablation": name},
        lambda d: chain_step.write_chain_fit(context, labels.split, detector, cfar_cells_for(base), base, d))
    params, fit = chain_step.read_chain_fit(fit_dir)
    row_dir, _, _ = run.step(
        f"{ABLATIONS_DIR}/{name}/row", {**base_inputs, "chain_fit": fit_key, "ablation": name},
        lambda d: scoring.score_into(d, scoring.cfar_predictions(context.dataset, params, fit), context.root))
    return Ablation(name, change, "cfar", Row(f"cfar-{name}", METHOD_NAMES["cfar"], False, False,
                                             [read_metrics(row_dir / "metrics.json")]), f"{ABLATIONS_DIR}/{name}/row")


def compare_ablations(run_path: Path, root: Path, ablations: list[Ablation], seeds: int,
                      matched: Mapping[str, Sequence[MatchedDetections]] | None = None) -> list[dict[str, Any]]:
    """``results.json``'s ``ablations``: each row's AP (mean over seeds) and its paired differences
    from its reference row per band (every seed, the claims' shared resamples and seed draws).

    ``matched``: the Table 1 rows' matchings the claims already made (row key → per seed,
    :func:`zendar_baselines.bench.claims.matched_seeds`); a reference row found there is not matched
    again. The others are matched from ``rows/<key>``.
    """
    from zendar_baselines.bench.claims import matched_predictions, seed_predictions, shared_resamples

    def row_dir(ablation: Ablation) -> Path:
        folder = run_path / ablation.folder  # a CNN row's first seed, or the CFAR row itself
        return folder.parent if folder.name.startswith("seed-") else folder

    known = {} if matched is None else matched
    paths = {ablation.row.key: seed_predictions(row_dir(ablation), seeds) for ablation in ablations}
    paths.update({ablation.reference: seed_predictions(run_path / "rows" / ablation.reference, seeds)
                  for ablation in ablations if ablation.reference not in known})
    matchings = matched_predictions(paths, root)
    matchings.update({ablation.reference: known[ablation.reference] for ablation in ablations
                      if ablation.reference in known})
    aps, resampling = shared_resamples(list(matchings), matchings)
    out = []
    for ablation in ablations:
        comparisons = {}
        for band in RANGE_BANDS:
            result = paired_difference(aps[ablation.row.key][band], aps[ablation.reference][band])
            comparisons[band] = {
                "difference": _round(result.difference), "ci95": [_round(result.low), _round(result.high)],
                "reading": READINGS.get(result.verdict, NO_DIFFERENCE),
            }
        out.append({"ablation": ablation.name, "change": ablation.change, "reference": ablation.reference,
                    "row": ablation.to_json(),
                    "minus_reference": comparisons, "resampling": resampling})
    return out


def markdown_ablations(records: list[dict[str, Any]], reference_aps: dict[str, dict[str, float | None]]) -> str:
    """The ablations' table: AP per band of the ablation row and its reference (means over seeds), and
    the paired difference of their seed means [95 % interval], in AP points."""
    lines = ["| ablation | change | band | AP ablation (seed mean) | AP reference (seed mean) | "
             "ablation − reference [95 % interval] | reading |",
             "|---|---|---|--:|--:|--:|---|"]
    for record in records:
        for band in (*RANGE_BANDS, "all"):
            ap = record["row"]["ap"][band]
            reference = reference_aps[record["reference"]][band]
            cell = "" if band == "all" else _difference_cell(record["minus_reference"][band])
            reading = "" if band == "all" else record["minus_reference"][band]["reading"]
            lines.append(f"| {record['ablation']} (vs {record['reference']}) | {record['change']} | {band} | "
                         f"{_percent(ap)} | {_percent(reference)} | {cell} | {reading} |")
    return "\n".join(lines) + "\n"


def _difference_cell(comparison: dict[str, Any]) -> str:
    difference, (low, high) = comparison["difference"], comparison["ci95"]
    if difference is None:
        return "n/a"
    shown = f"{100 * difference:+.1f}"
    return shown if low is None else f"{shown} [{100 * low:+.1f}, {100 * high:+.1f}]"


def _percent(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.1f}"


def _round(value: float | None) -> float | None:
    return None if value is None else round(float(value), 4)
