"""How noisy the automatic labels are: automatic masks against masks made from the manual labels.

Both inputs are range-Doppler masks ``[N, R, D]`` (values BACKGROUND, MOVING, UNCERTAIN) of the same
cubes. Figures are given per range band of the evaluator (``zendar_dataset.eval.protocol.BANDS_M``:
near [0, 15), mid [15, 30), far [30, 60) m, and all [0, 60) m; range bins at 60 m or beyond are in
no band), each with the counts it is made of:

- cell precision and recall of MOVING. A cell marked UNCERTAIN in *either* mask is left out of both:
  the automatic masks' UNCERTAIN cells are the paper's "cannot tell" class (Fig. 2), and the label
  masks' UNCERTAIN cells are the margin around a box where range and DOA error blur the truth.
- the share of cells the automatic masks mark UNCERTAIN.
- object recall: the share of connected MOVING segments of the label masks that overlap at least one
  automatic MOVING cell; object precision: the share of automatic MOVING segments that overlap at
  least one label MOVING cell. Segments are 4-connected within one frame (``scipy.ndimage.label``'s
  default; the Doppler axis is not wrapped) and belong to the band of their mean range.

A ratio is None where its denominator is zero. :func:`combine_quality` adds results up over scenes
and radars by summing counts, then dividing.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
from scipy import ndimage

from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.protocol import BANDS_M
from zendar_dataset.eval.report import format_percent

from zendar_baselines.labels.mask_classes import BACKGROUND, MASK_CLASSES, MOVING, UNCERTAIN
from zendar_baselines.labels.masks import MaskParams

#: The manual-label masks automatic labels are measured against: the CFAR-gated kind, not the box
#: targets the CNNs train on. Automatic labels are made from CFAR peaks, so the figures measure which of
#: the peaks on labelled cars they keep, and keep their meaning.
QUALITY_REFERENCE = MaskParams(manual_targets="cfar-peaks")
COUNT_NAMES = (
    "cells",
    "uncertain_cells",
    "excluded_cells",
    "tp_cells",
    "fp_cells",
    "fn_cells",
    "label_segments",
    "label_segments_found",
    "auto_segments",
    "auto_segments_matched",
)
#: ratio name → (numerator count, denominator counts summed)
RATIOS = {
    "cell_precision": ("tp_cells", ("tp_cells", "fp_cells")),
    "cell_recall": ("tp_cells", ("tp_cells", "fn_cells")),
    "uncertain_share": ("uncertain_cells", ("cells",)),
    "object_recall": ("label_segments_found", ("label_segments",)),
    "object_precision": ("auto_segments_matched", ("auto_segments",)),
}
# Connected within a frame only: the same car in consecutive cubes is two segments, one per cube.
_IN_FRAME = np.zeros((3, 3, 3), dtype=bool)
_IN_FRAME[1] = ndimage.generate_binary_structure(2, 1)
# Bounds the boolean temporaries to a few tens of MB whatever the scene length.
_FRAMES_PER_BLOCK = 64


def _mask_problems(name: str, masks: np.ndarray) -> list[str]:
    if masks.ndim != 3:
        return [f"{name}: expected masks [N, R, D], found shape {list(masks.shape)}"]
    if not np.issubdtype(masks.dtype, np.integer):
        return [f"{name}: expected integer masks (uint8), found {masks.dtype}"]
    n_bad = int(np.count_nonzero((masks < min(MASK_CLASSES)) | (masks > max(MASK_CLASSES)))) if masks.size else 0
    return [f"{name}: expected values in {list(MASK_CLASSES)}, found {n_bad} cells outside"] if n_bad else []


def _check_inputs(auto_masks: np.ndarray, label_masks: np.ndarray, range_m: np.ndarray) -> None:
    problems = _mask_problems("auto_masks", auto_masks) + _mask_problems("label_masks", label_masks)
    if auto_masks.shape != label_masks.shape:
        problems.append(
            f"expected auto_masks and label_masks of one shape, found {list(auto_masks.shape)} and {list(label_masks.shape)}"
        )
    n_range = auto_masks.shape[1] if auto_masks.ndim == 3 else None
    if range_m.ndim != 1 or (n_range is not None and range_m.shape[0] != n_range):
        problems.append(f"range_m: expected one range per range bin [{n_range}], found shape {list(range_m.shape)}")
    elif not np.all(np.isfinite(range_m)):
        problems.append("range_m: expected finite ranges, found NaN or infinity")
    if problems:
        raise ZendarError("; ".join(problems))


def _segment_hits(segment_ids: np.ndarray, n_segments: int, other: np.ndarray) -> np.ndarray:
    """bool ``[n_segments]``: whether each segment has at least one cell where ``other`` is True."""
    hit = np.zeros(n_segments + 1, dtype=bool)
    hit[segment_ids[other & (segment_ids > 0)]] = True
    return hit[1:]


def _segment_mean_range_m(segment_ids: np.ndarray, n_segments: int, range_m: np.ndarray) -> np.ndarray:
    """float ``[n_segments]``: mean range (m) over each segment's cells."""
    cells = np.nonzero(segment_ids)
    which = segment_ids[cells]
    total_m = np.bincount(which, weights=range_m[cells[1]], minlength=n_segments + 1)
    size = np.bincount(which, minlength=n_segments + 1)
    return total_m[1:] / np.maximum(size[1:], 1)


def _with_ratios(n_frames: int, counts: dict[str, dict[str, int]]) -> dict[str, Any]:
    bands = {}
    for band, (low_m, high_m) in BANDS_M.items():
        entry: dict[str, Any] = {"range_m": [low_m, high_m], "counts": dict(counts[band])}
        for ratio, (numerator, denominator) in RATIOS.items():
            total = sum(counts[band][name] for name in denominator)
            entry[ratio] = counts[band][numerator] / total if total else None
        bands[band] = entry
    return {"n_frames": n_frames, "bands": bands}


def mask_quality(auto_masks: np.ndarray, label_masks: np.ndarray, range_m: np.ndarray) -> dict[str, Any]:
    """Cell- and object-level agreement of automatic masks with label masks, per range band.

    Parameters
    ----------
    auto_masks
        uint8 ``[N, R, D]``: automatic masks of N cubes of one radar.
    label_masks
        uint8 ``[N, R, D]``: masks made from the manual labels for the same cubes.
    range_m
        float ``[R]``: range (m) of each range bin.

    Returns
    -------
    dict
        ``{"n_frames": N, "bands": {band: {"range_m": [low, high], "counts": {name: int for name in
        COUNT_NAMES}, "cell_precision", "cell_recall", "uncertain_share", "object_recall",
        "object_precision"}}}`` with each ratio a float or None (zero denominator); the rules are
        in the module docstring.

    Raises
    ------
    ZendarError
        Listing every problem with the shapes, dtypes, values or ranges.
    """
    auto_masks, label_masks, range_m = np.asarray(auto_masks), np.asarray(label_masks), np.asarray(range_m, dtype=float)
    _check_inputs(auto_masks, label_masks, range_m)
    n_frames, _, n_doppler = auto_masks.shape
    rows_in_band = {band: (range_m >= low_m) & (range_m < high_m) for band, (low_m, high_m) in BANDS_M.items()}
    counts = {band: dict.fromkeys(COUNT_NAMES, 0) for band in BANDS_M}
    for start in range(0, n_frames, _FRAMES_PER_BLOCK):
        auto = auto_masks[start : start + _FRAMES_PER_BLOCK]
        label = label_masks[start : start + _FRAMES_PER_BLOCK]
        auto_moving, label_moving = auto == MOVING, label == MOVING
        auto_uncertain = auto == UNCERTAIN
        per_row = {
            "uncertain_cells": auto_uncertain,
            "excluded_cells": auto_uncertain | (label == UNCERTAIN),
            "tp_cells": auto_moving & label_moving,
            "fp_cells": auto_moving & (label == BACKGROUND),
            "fn_cells": (auto == BACKGROUND) & label_moving,
        }
        per_row = {name: cells.sum(axis=(0, 2)) for name, cells in per_row.items()}
        label_ids, n_label = ndimage.label(label_moving, structure=_IN_FRAME)
        auto_ids, n_auto = ndimage.label(auto_moving, structure=_IN_FRAME)
        label_found = _segment_hits(label_ids, n_label, auto_moving)
        auto_matched = _segment_hits(auto_ids, n_auto, label_moving)
        label_range_m = _segment_mean_range_m(label_ids, n_label, range_m)
        auto_range_m = _segment_mean_range_m(auto_ids, n_auto, range_m)
        for band, (low_m, high_m) in BANDS_M.items():
            band_counts, rows = counts[band], rows_in_band[band]
            band_counts["cells"] += int(auto.shape[0] * np.count_nonzero(rows) * n_doppler)
            for name, row_counts in per_row.items():
                band_counts[name] += int(row_counts[rows].sum())
            label_in = (label_range_m >= low_m) & (label_range_m < high_m)
            auto_in = (auto_range_m >= low_m) & (auto_range_m < high_m)
            band_counts["label_segments"] += int(np.count_nonzero(label_in))
            band_counts["label_segments_found"] += int(np.count_nonzero(label_found & label_in))
            band_counts["auto_segments"] += int(np.count_nonzero(auto_in))
            band_counts["auto_segments_matched"] += int(np.count_nonzero(auto_matched & auto_in))
    return _with_ratios(n_frames, counts)


def combine_quality(results: Iterable[dict[str, Any]]) -> dict[str, Any]:
    """Add up :func:`mask_quality` results (of scenes, radars): counts summed, then ratios recomputed.

    Raises
    ------
    ZendarError
        When a result does not have the bands and counts of :func:`mask_quality`.
    """
    n_frames = 0
    counts = {band: dict.fromkeys(COUNT_NAMES, 0) for band in BANDS_M}
    for index, result in enumerate(results):
        try:
            n_frames += int(result["n_frames"])
            for band in BANDS_M:
                for name in COUNT_NAMES:
                    counts[band][name] += int(result["bands"][band]["counts"][name])
        except (KeyError, TypeError, ValueError) as exc:
            raise ZendarError(f"result {index}: expected the output of mask_quality, found no {exc}") from None
    return _with_ratios(n_frames, counts)


def format_quality(quality: dict[str, Any]) -> str:
    """A plain-text table of a :func:`mask_quality` or :func:`combine_quality` result (percent).

    Returns
    -------
    str
        Several lines, no trailing newline.
    """
    columns = (
        f"{'band':<5} {'range [m]':<10} {'cell P':>7} {'cell R':>7} {'uncert.':>7} {'obj R':>7} {'obj P':>7}"
        f" {'TP cells':>9} {'FP cells':>9} {'FN cells':>9} {'label seg':>9} {'auto seg':>9}"
    )
    lines = [f"automatic vs label masks, {quality['n_frames']} frames (ratios in %)", columns, "-" * len(columns)]
    for band, entry in quality["bands"].items():
        low_m, high_m = entry["range_m"]
        counts = entry["counts"]
        lines.append(
            f"{band:<5} {f'[{low_m:g}, {high_m:g})':<10}"
            + "".join(f" {format_percent(entry[ratio]):>7}" for ratio in RATIOS)
            + f" {counts['tp_cells']:>9} {counts['fp_cells']:>9} {counts['fn_cells']:>9}"
            + f" {counts['label_segments']:>9} {counts['auto_segments']:>9}"
        )
    lines += [
        "cell P / R: precision / recall of MOVING cells; cells UNCERTAIN in either mask are left out",
        "uncert.: share of cells the automatic masks mark UNCERTAIN",
        "obj R: label segments overlapping an automatic MOVING cell; obj P: automatic segments overlapping a label MOVING cell",
        "segments: 4-connected within a frame, in the band of their mean range; n/a: nothing to divide by",
    ]
    return "\n".join(lines)


__all__ = ["COUNT_NAMES", "QUALITY_REFERENCE", "RATIOS", "combine_quality", "format_quality", "mask_quality"]
