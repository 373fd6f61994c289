"""``zendar-bench verify``: re-score a finished run from its checkpoints.

Every CNN row's checkpoints are loaded (their SHA-256 manifest and architecture checked), the test
split is predicted again and scored by the official evaluator; the CFAR row is recomputed from the
cubes. A row reproduces when every band's AP is within its tolerance of what the run recorded:
:data:`CFAR_AP_TOLERANCE` for the CFAR row, which reproduces exactly on every machine tried, and
:data:`CNN_AP_TOLERANCE` for the CNN rows, the spread measured between machines of another vector
width: the same ``zendar-bench`` on an AVX2 and an AVX-512 CPU gave CNN rows up to 1.3 AP points
apart (the CFAR row identical), because oneDNN's convolutions and ATen's vectorised reductions sum
in another order on each, and training compounds the rounding over thousands of steps. On one
machine verifying a run is exact.

The claims' paired intervals are recomputed from the run's recorded predictions of every seed (the same
resamples, so the same numbers): each comparison's verdict must be the recorded one. A results file
whose ``claims`` predate paired intervals (no ``comparisons``) has them skipped, and says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from zendar_dataset.errors import ZendarError
from zendar_dataset.eval import evaluate_record
from zendar_dataset.eval.protocol import BAND_NAMES
from zendar_dataset.eval.report import format_percent, read_metrics

from zendar_baselines.bench.configs import BenchConfig, Schedule
from zendar_baselines.bench.run_directory import RUN_MARKER, read_json

if TYPE_CHECKING:
    from zendar_baselines.bench.scoring import ScoringScenes

#: Largest |AP difference| per band (fraction) for the CFAR row to count as reproduced.
CFAR_AP_TOLERANCE = 0.01
#: Largest |AP difference| per band (fraction) for a CNN row: the cross-machine spread measured
#: (0.013, AVX2 against AVX-512), rounded up.
CNN_AP_TOLERANCE = 0.015
BANDS = BAND_NAMES


def ap_tolerance(row_key: str) -> float:
    """Largest |AP difference| per band for a row to count as reproduced: CFAR's or the CNN rows'."""
    return CFAR_AP_TOLERANCE if row_key == "cfar" else CNN_AP_TOLERANCE


@dataclass(frozen=True)
class VerifyReport:
    """Outcome of :func:`verify_run`: ``reproduced`` for every row, and a readable ``text``."""

    reproduced: bool
    text: str


def _config_from_json(document: dict) -> BenchConfig:
    fields = dict(document)
    for phase in ("pretrain", "finetune", "supervised"):
        fields[phase] = Schedule(**fields[phase])
    fields["models"] = tuple(fields["models"])
    return BenchConfig(**fields)


def verify_run(out: Path, device: str = "cpu") -> VerifyReport:
    """Re-score every row of the run in ``out``; see the module docstring.

    Raises
    ------
    ZendarError
        When ``out`` is not a finished zendar-bench run, or a checkpoint is missing or corrupt.
    """
    from zendar_baselines.bench.scoring import ScoringScenes

    if not (out / RUN_MARKER).is_file() or not (out / "results.json").is_file():
        raise ZendarError(f"--out {out}: not a finished zendar-bench run (no {RUN_MARKER} and results.json)")
    results = read_json(out / "results.json")
    if isinstance(results, dict) and results.get("manual_labels") is False:
        raise ZendarError(f"--out {out}: a run on a dataset without manual labels scored nothing, so there is nothing to re-score")
    try:
        config = _config_from_json(results["config"])
        root = Path(results["dataset"]["root"])
        rows = results["rows"]
    except (KeyError, TypeError) as exc:
        raise ZendarError(f"{out / 'results.json'}: not a zendar-bench results file ({exc!r} missing)") from None
    lines = [f"re-scoring {out} (tolerance per band: {CFAR_AP_TOLERANCE:g} AP for CFAR, {CNN_AP_TOLERANCE:g} for the "
             "CNN rows, their spread across CPUs)"]
    all_reproduced = True
    with ScoringScenes(root) as test_scenes:
        for row in rows:
            all_reproduced &= _verify_row(out, row, root, config, device, test_scenes, lines)
    all_reproduced &= _verify_claims(out, results, root, lines)
    lines.append("every row reproduces" if all_reproduced else "some rows do not reproduce within the tolerance")
    return VerifyReport(all_reproduced, "\n".join(lines))


def _verify_claims(out: Path, results: dict, root: Path, lines: list[str]) -> bool:
    """Recompute the claims from the recorded predictions; True when every verdict is the recorded one."""
    from zendar_baselines.bench.claims import claim_verdicts, matched_seeds
    from zendar_baselines.bench.results_table import Row

    recorded = results.get("claims")
    if not isinstance(recorded, dict) or not all(isinstance(c, dict) and "comparisons" in c for c in recorded.values()):
        lines.append("  claims: recorded without paired intervals (an older results.json), not recomputed")
        return True
    rows = [Row(r["key"], r["method"], r["unsupervised"], r["supervised"]) for r in results["rows"]]
    resampling = next(iter(recorded.values()))["resampling"]
    # Runs of before 3 December compared first seeds only.
    seeds = 1 if resampling.get("seeds_compared") == "first" else int(results["seeds"])
    again = claim_verdicts(rows, matched_seeds(out, rows, root, seeds), block_s=resampling["block_s"],
                           n_resamples=resampling["n_resamples"], seed=resampling["seed"])
    differing = [
        f"{name} {was['pair']} {was['band']}: {was['verdict']} -> {now['verdict']}"
        for name in recorded
        for was, now in zip(recorded[name]["comparisons"], again.get(name, {}).get("comparisons", []))
        if was["verdict"] != now["verdict"]
    ]
    counts_differ = [name for name in recorded
                     if len(recorded[name]["comparisons"]) != len(again.get(name, {}).get("comparisons", []))]
    ok = not differing and not counts_differ
    n = sum(len(claim["comparisons"]) for claim in recorded.values())
    lines.append(f"  {'ok  ' if ok else 'DIFF'} claims: {n} paired comparisons recomputed from the recorded predictions"
                 + "".join(f"\n       {line}" for line in differing)
                 + "".join(f"\n       {name}: another number of comparisons" for name in counts_differ))
    return ok


def _verify_row(out: Path, row: dict, root: Path, config: BenchConfig, device: str,
                test_scenes: ScoringScenes, lines: list[str]) -> bool:
    """Re-score every seed of one row, appending a line each; True when all reproduce."""
    from zendar_baselines.bench.chain_step import CFAR_STEP, read_chain_fit
    from zendar_baselines.bench.scoring import cfar_predictions, cnn_predictions
    from zendar_baselines.bench.steps import final_checkpoint

    key = row["key"]
    seed_dirs = sorted((out / "rows" / key).glob("seed-*")) if key != "cfar" else [out / "rows" / key]
    if not seed_dirs:
        raise ZendarError(f"{out / 'rows' / key}: no seed directories to re-score")
    all_reproduced = True
    for seed_dir in seed_dirs:
        recorded = read_metrics(seed_dir / "metrics.json").ap
        if key == "cfar":
            params, _ = read_chain_fit(out / CFAR_STEP)
            predictions = cfar_predictions(test_scenes.index, params)
        else:
            params, _ = read_chain_fit(seed_dir)
            predictions = cnn_predictions(test_scenes.index, config, final_checkpoint(seed_dir), device, params, test_scenes)
        again = evaluate_record(predictions, str(root), split="test").ap
        worst = max((abs(again[b] - recorded[b]) for b in BANDS if again[b] is not None and recorded[b] is not None),
                    default=0.0)
        same_bands = all((again[b] is None) == (recorded[b] is None) for b in BANDS)
        ok = same_bands and worst <= ap_tolerance(key) and not math.isnan(worst)
        all_reproduced &= ok
        shown = " ".join(f"{b} {format_percent(recorded[b])}->{format_percent(again[b])}" for b in BANDS)
        lines.append(f"  {'ok  ' if ok else 'DIFF'} {seed_dir.relative_to(out)}: {shown} (max |diff| {worst:.4f})")
    return all_reproduced
