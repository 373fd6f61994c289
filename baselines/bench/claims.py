"""The paper's three claims, each decided by paired bootstrap intervals of AP differences.

- ``cnn_beats_cfar``: every CNN row (supervised-only and pretrained) above CFAR, per band;
- ``pretraining_helps``: per architecture, pretrain → fine-tune above supervised-only, per band;
- ``ap_falls_with_range``: per row, near above mid and mid above far (two bands of one row, over the
  same resamples).

Every comparison uses every seed of each row, matched by the official evaluator
(:func:`zendar_dataset.eval.evaluate.matched_detections`), and the same resamples of the test split's
units: each scene's frames cut into time blocks of :data:`BLOCK_S` (see docs/baselines.md for why that
length). A row is the mean of its seeds' APs; in every resample its seeds are drawn with replacement
(:func:`zendar_dataset.eval.paired.pooled_over_seeds`; the same draws for the bands of one row,
independent draws per row), so an interval holds the spread between trainings as well as that of the
test frames. With one seed per row this is the plain paired bootstrap. A comparison holds when its whole 95 %
interval is above 0, fails when it is below, and is undecided when it contains 0; a claim holds when
every comparison holds, fails when any fails, and is undecided otherwise.
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.bootstrap import distinct_resamples, resample_weights
from zendar_dataset.eval.evaluate import MatchedDetections, frame_units, matched_detections
from zendar_dataset.eval.paired import (
    FAILS,
    HOLDS,
    UNDECIDED,
    PairedDifference,
    ResampledAP,
    paired_difference,
    pooled_over_seeds,
    resampled_ap,
    seed_draws,
    too_few_resamples,
)
from zendar_dataset.eval.protocol import BOOTSTRAP_CONFIDENCE, BOOTSTRAP_UNIT_BLOCK, RANGE_BANDS

from zendar_baselines.bench.results_table import Row

#: Time block (s) of the test split's resampling units. The per-frame count of labelled cars in a band
#: decorrelates (autocorrelation below 1/e) within 0.2-1.1 s in the demo dataset, and a car stays in a
#: band for 1.5 s (median); 2 s blocks are about twice the longest correlation time.
BLOCK_S = 2.0
#: Resamples of every paired comparison (the same for all; percentiles of 95 % intervals settle well before).
CLAIM_RESAMPLES = 1000
#: Seed of the shared resamples.
CLAIM_SEED = 0

CLAIM_NAMES = ("cnn_beats_cfar", "pretraining_helps", "ap_falls_with_range")
STATEMENTS = {
    "cnn_beats_cfar": "every CNN row has higher AP than CFAR, per band",
    "pretraining_helps": "per architecture, pretrain + fine-tune has higher AP than supervised only, per band",
    "ap_falls_with_range": "per row, AP near > mid > far",
}


@dataclass(frozen=True)
class Comparison:
    """One paired comparison of a claim.

    Attributes
    ----------
    pair : str
        Readable ``"A − B"``, A the side claimed better.
    better, worse : str
        Row keys of A and B (the same row for a comparison of bands).
    band : str
        The band (``"near"``), or ``"near − mid"`` for a comparison of two bands of one row.
    result : PairedDifference
    """

    pair: str
    better: str
    worse: str
    band: str
    result: PairedDifference

    def to_json(self) -> dict[str, Any]:
        result = self.result
        return {
            "pair": self.pair, "better": self.better, "worse": self.worse, "band": self.band,
            "difference": _round(result.difference), "ci95": [_round(result.low), _round(result.high)],
            "n_resamples": result.n, "verdict": result.verdict,
        }


def _round(value: float | None) -> float | None:
    return None if value is None else round(float(value), 4)


def row_label(row: Row) -> str:
    """The row as tables name it: method, and how it was trained for a CNN."""
    if not row.supervised:
        return row.method
    return f"{row.method} ({'pretrained' if row.unsupervised else 'supervised only'})"


def overall_verdict(comparisons: list[Comparison]) -> str:
    """``fails`` when any comparison fails, ``holds`` when all (at least one) hold, else ``undecided``."""
    verdicts = [c.result.verdict for c in comparisons]
    if FAILS in verdicts:
        return FAILS
    if verdicts and all(v == HOLDS for v in verdicts):
        return HOLDS
    return UNDECIDED


def claim_comparisons(rows: list[Row], aps: Mapping[str, Mapping[str, ResampledAP]]) -> dict[str, list[Comparison]]:
    """Every comparison of the three claims, from each row's resampled AP per band.

    Parameters
    ----------
    rows
        Table 1's rows (CFAR first or anywhere).
    aps
        Row key → band → its AP on all frames and in each of the shared resamples.
    """
    cfar = next((row for row in rows if row.method == "CFAR"), None)
    cnn_rows = [row for row in rows if row.supervised]
    out: dict[str, list[Comparison]] = {name: [] for name in CLAIM_NAMES}

    def compare(better: Row, worse: Row, band: str) -> Comparison:
        return Comparison(f"{row_label(better)} − {row_label(worse)}", better.key, worse.key, band,
                          paired_difference(aps[better.key][band], aps[worse.key][band]))

    if cfar is not None:
        out["cnn_beats_cfar"] = [compare(row, cfar, band) for row in cnn_rows for band in RANGE_BANDS]
    by_method = {(row.method, row.unsupervised): row for row in cnn_rows}
    for method in dict.fromkeys(row.method for row in cnn_rows):
        if (method, True) in by_method and (method, False) in by_method:
            out["pretraining_helps"] += [compare(by_method[(method, True)], by_method[(method, False)], band)
                                         for band in RANGE_BANDS]
    for row in rows:
        for near, far in zip(RANGE_BANDS, RANGE_BANDS[1:]):
            out["ap_falls_with_range"].append(Comparison(
                row_label(row), row.key, row.key, f"{near} − {far}",
                paired_difference(aps[row.key][near], aps[row.key][far])))
    return out


def claim_verdicts(rows: list[Row], matched: Mapping[str, Sequence[MatchedDetections]], *, block_s: float = BLOCK_S,
                   n_resamples: int = CLAIM_RESAMPLES, seed: int = CLAIM_SEED) -> dict[str, Any]:
    """``results.json``'s ``claims``: per claim its comparisons, their intervals and verdicts.

    Parameters
    ----------
    rows
        Table 1's rows.
    matched
        Row key → the evaluator's matching of each of the row's seeds' predictions on the test split,
        in seed order (:func:`matched_seeds`).
    block_s, n_resamples, seed
        The shared resamples: units are each scene's time blocks of ``block_s``.

    Returns
    -------
    dict
        ``{claim: {"statement", "verdict", "resampling", "comparisons": [...]}}``.

        When the split has too few blocks for
        :data:`~zendar_dataset.eval.protocol.MIN_DISTINCT_RESAMPLES` distinct resamples,
        ``resampling["problem"]`` says so, no interval is computed and every verdict is undecided.

    Raises
    ------
    ZendarError
        When the rows were not scored on the same frames.
    """
    aps, resampling = shared_resamples([row.key for row in rows], matched, block_s=block_s, n_resamples=n_resamples,
                                       seed=seed)
    return {
        name: {"statement": STATEMENTS[name], "verdict": overall_verdict(comparisons), "resampling": resampling,
               "comparisons": [c.to_json() for c in comparisons]}
        for name, comparisons in claim_comparisons(rows, aps).items()
    }


def shared_resamples(keys: list[str], matched: Mapping[str, Sequence[MatchedDetections]], *, block_s: float = BLOCK_S,
                     n_resamples: int = CLAIM_RESAMPLES, seed: int = CLAIM_SEED
                     ) -> tuple[dict[str, dict[str, ResampledAP]], dict[str, Any]]:
    """Each row's AP per band (the mean over its seeds) on all frames and in the same resamples of
    the test split's time blocks, its seeds drawn with replacement in every resample (module docstring).

    Returns
    -------
    aps, resampling
        Key → band → :class:`ResampledAP`; and the resampling's record (``seeds``: how many seeds
        each row pooled; ``problem`` when the split has too few blocks: then no resample is drawn and
        every interval is None).

    Raises
    ------
    ZendarError
        When a row has no seed, or the rows' seeds were not scored on the same frames.
    """
    for key in keys:
        if isinstance(matched[key], MatchedDetections):
            raise ZendarError(f"row {key}: give a list of its seeds' matchings (one item for one seed), not a bare matching")
        if not matched[key]:
            raise ZendarError(f"row {key}: no seed's predictions to compare")
    first = matched[keys[0]][0]
    for key in keys:
        if any(seed_matched.frame_ids != first.frame_ids for seed_matched in matched[key]):
            raise ZendarError(f"row {key}: scored on other frames than row {keys[0]}; paired "
                              "comparisons need the same frames")
    frame_unit, n_units = frame_units(first.frame_ids, first.evaluated_frame, block_s)
    problem = too_few_resamples(n_units, f"test split, {block_s:g} s time blocks")
    # Too few units: no resample at all, so every comparison keeps its difference and no interval.
    weights = resample_weights(n_units, 0 if problem else n_resamples, seed)
    aps = {}
    for key in keys:
        per_seed = [seed_matched.band_detections(frame_unit) for seed_matched in matched[key]]
        # A row's draws depend on the row's key and the seed alone, not on which other rows are compared.
        draws = seed_draws(weights.shape[0], len(per_seed), np.random.default_rng([seed, zlib.crc32(key.encode())]))
        aps[key] = {band: pooled_over_seeds([resampled_ap(bands[band], weights) for bands in per_seed], draws)
                    for band in RANGE_BANDS}
    resampling = {
        "unit": BOOTSTRAP_UNIT_BLOCK, "block_s": block_s, "n_units": n_units,
        "distinct_resamples": distinct_resamples(n_units), "n_resamples": n_resamples, "seed": seed,
        "confidence": BOOTSTRAP_CONFIDENCE, "seeds_compared": "all",
        "seeds": {key: len(matched[key]) for key in keys},
    }
    if problem:
        resampling["problem"] = problem
    return aps, resampling


def seed_predictions(row_dir: Path, seeds: int) -> list[Path]:
    """A row's predictions files, in seed order: ``seed-<k>/predictions.json`` for ``k < seeds`` when
    the row has seed folders (a CNN row), else its one ``predictions.json`` (CFAR)."""
    if (row_dir / "seed-0").is_dir():
        return [row_dir / f"seed-{k}" / "predictions.json" for k in range(seeds)]
    return [row_dir / "predictions.json"]


def matched_seeds(run_path: Path, rows: list[Row], root: Path, seeds: int) -> dict[str, list[MatchedDetections]]:
    """Row key → the evaluator's matching of each of the row's ``seeds`` seeds' predictions on the test
    split (:func:`seed_predictions` of ``rows/<key>``)."""
    return matched_predictions({row.key: seed_predictions(run_path / "rows" / row.key, seeds) for row in rows}, root)


def matched_predictions(paths: Mapping[str, Sequence[Path]], root: Path) -> dict[str, list[MatchedDetections]]:
    """Key → the evaluator's matching of each predictions file of ``paths[key]`` on the test split of ``root``."""
    from zendar_dataset.format.ground_truth import ground_truth_frames

    ground_truth = {"frames": ground_truth_frames(root, "test"), "split": "test"}
    return {key: [matched_detections(path, ground_truth, split="test") for path in files] for key, files in paths.items()}


def markdown_claims(verdicts: Mapping[str, Any]) -> str:
    """The claims table: claim, pair, band, difference [95 % interval] (AP points), verdict."""
    lines = ["| claim | pair | band | difference [95 % interval] | verdict |", "|---|---|---|--:|---|"]
    for name, claim in verdicts.items():
        for c in claim["comparisons"]:
            low, high = c["ci95"]
            shown = "n/a" if c["difference"] is None else f"{100 * c['difference']:+.1f}"
            if low is not None:
                shown += f" [{100 * low:+.1f}, {100 * high:+.1f}]"
            lines.append(f"| {name.replace('_', ' ')} | {c['pair']} | {c['band']} | {shown} | {c['verdict']} |")
    summary = [f"- {name.replace('_', ' ')} ({claim['statement']}): **{claim['verdict']}**"
               for name, claim in verdicts.items()]
    resampling = next(iter(verdicts.values()))["resampling"] if verdicts else None
    if resampling is not None and "problem" in resampling:
        return "\n".join(lines) + "\n\n" + "\n".join(summary) + f"\n\n**No intervals**: {resampling['problem']}.\n"
    note = "" if resampling is None else (
        f"\nPaired bootstrap over every seed (a row is the mean of its seeds' AP; its seeds drawn with replacement "
        f"in every resample): {resampling['n_resamples']} shared resamples of "
        f"{resampling['n_units']} units ({resampling['block_s']:g} s time blocks of the test scenes; "
        f"{resampling['distinct_resamples']:,} distinct resamples possible); holds: interval above 0, "
        "fails: below 0, undecided: contains 0.\n")
    return "\n".join(lines) + "\n\n" + "\n".join(summary) + "\n" + note
