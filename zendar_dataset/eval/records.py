"""Typed records of what the evaluator produces: ``metrics.json`` as frozen dataclasses.

:func:`zendar_dataset.eval.evaluate.evaluate_record` returns a :class:`MetricsRecord`.
``record.to_json()`` is exactly the dict that :func:`zendar_dataset.eval.evaluate` returns and
``zendar-eval --out`` writes (same keys, same order, same values), and
``MetricsRecord.from_json(metrics)`` reads such a dict back, checking every member. Per-band members
are keyed by the protocol's band names (:data:`~zendar_dataset.eval.protocol.BAND_NAMES`), every
band present, in that order.
"""

from __future__ import annotations

import copy
import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.protocol import BAND_NAMES

_Record = TypeVar("_Record")


def _kind(value: Any) -> str:
    return "null" if value is None else type(value).__name__


def _is_number(value: Any) -> bool:
    # bool is an int to Python, never a number in these files.
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _object(value: Any, where: str, required: tuple[str, ...], optional: tuple[str, ...],
            problems: list[str]) -> bool:
    """Whether ``value`` is an object; names each ``required`` member it lacks and each unknown one."""
    if not isinstance(value, dict):
        problems.append(f"{where}: expected an object, found {_kind(value)}")
        return False
    missing = [key for key in required if key not in value]
    unexpected = [key for key in value if key not in required and key not in optional]
    if missing:
        problems.append(f"{where}: missing {', '.join(map(repr, missing))}")
    if unexpected:
        problems.append(f"{where}: unexpected {', '.join(map(repr, unexpected))}")
    return True


def _member(value: dict, key: str, where: str, read: Callable[[Any, str, list[str]], Any],
            problems: list[str], default: Any = None) -> Any:
    """``read(value[key])``, or ``default`` when the member is absent (already named by :func:`_object`)."""
    return read(value[key], f"{where}.{key}", problems) if key in value else default


def _mapping(value: Any, where: str, problems: list[str]) -> dict[str, Any]:
    """A free-form object (``protocol``, ``meta``), copied so that the record owns it."""
    if not isinstance(value, dict):
        problems.append(f"{where}: expected an object, found {_kind(value)}")
        return {}
    return copy.deepcopy(value)


def _flag(value: Any, where: str, problems: list[str]) -> bool:
    if not isinstance(value, bool):
        problems.append(f"{where}: expected true or false, found {value!r}")
        return False
    return value


def _text(value: Any, where: str, problems: list[str]) -> str | None:
    if not isinstance(value, str):
        problems.append(f"{where}: expected a string, found {_kind(value)}")
        return None
    return value


def _count(value: Any, where: str, problems: list[str]) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        problems.append(f"{where}: expected an integer 0 or more, found {value!r}")
        return 0
    return value


def _fraction(value: Any, where: str, problems: list[str]) -> float | None:
    """An AP-like value: a finite number, or None (null).

    Not range-checked: a sum of recall steps can land one rounding step above 1.
    """
    if value is None:
        return None
    if not _is_number(value) or not math.isfinite(value):
        problems.append(f"{where}: expected a finite number or null, found {value!r}")
        return None
    return float(value)


def _numbers(value: Any, where: str, problems: list[str]) -> tuple[float, ...]:
    if not isinstance(value, list):
        problems.append(f"{where}: expected a list of numbers, found {_kind(value)}")
        return ()
    bad = [k for k, item in enumerate(value) if not _is_number(item) or not math.isfinite(item)]
    if bad:
        problems.append(f"{where}: expected finite numbers, found {value[bad[0]]!r} at index {bad[0]}"
                        + (f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""))
        return ()
    return tuple(float(item) for item in value)


def _by_band(read: Callable[[Any, str, list[str]], _Record], value: Any, where: str,
             problems: list[str]) -> dict[str, _Record]:
    """Band name → ``read(member)``, for an object keyed by exactly the protocol's bands."""
    if not _object(value, where, BAND_NAMES, (), problems):
        return {}
    return {band: read(value[band], f"{where}.{band}", problems) for band in BAND_NAMES if band in value}


def _checked(read: Callable[[Any, str, list[str]], _Record], value: Any, where: str,
             source: str | None) -> _Record:
    """``read(value)``, or ZendarError listing every problem (each prefixed by ``source`` when given)."""
    problems: list[str] = []
    record = read(value, where, problems)
    if problems:
        prefix = f"{source}: " if source else ""
        noun = "problem" if len(problems) == 1 else "problems"
        raise ZendarError(
            f"{prefix}{len(problems)} {noun} in the evaluator's {where}: " + "; ".join(problems),
            [prefix + problem for problem in problems],
        )
    return record


@dataclass(frozen=True)
class BandCounts:
    """One band's ground truths and the true and false positives counted in it.

    Attributes
    ----------
    gt, tp, fp : int
        Ground truths in the band; matched predictions counted in it (their ground truth's band);
        unmatched predictions counted in it (their own band).
    """

    gt: int
    tp: int
    fp: int

    def to_json(self) -> dict[str, int]:
        """``{"gt": int, "tp": int, "fp": int}``."""
        return {"gt": self.gt, "tp": self.tp, "fp": self.fp}

    @classmethod
    def from_json(cls, value: Any, source: str | None = None) -> BandCounts:
        """Read ``{"gt", "tp", "fp"}``; ZendarError naming every missing or wrong member."""
        return _checked(cls._read, value, "counts", source)

    @classmethod
    def _read(cls, value: Any, where: str, problems: list[str]) -> BandCounts:
        if not _object(value, where, ("gt", "tp", "fp"), (), problems):
            return cls(0, 0, 0)
        return cls(*(_member(value, key, where, _count, problems, 0) for key in ("gt", "tp", "fp")))


@dataclass(frozen=True)
class BootstrapInterval:
    """One band's percentile confidence interval of AP over scene resamples.

    Attributes
    ----------
    low, high : float or None
        Interval ends in [0, 1]; both None when no resample had ground truth in the band.
    n : int
        Resamples in which the band had ground truth (AP defined).
    """

    low: float | None
    high: float | None
    n: int

    def to_json(self) -> dict[str, Any]:
        """``{"low": float | None, "high": float | None, "n": int}``."""
        return {"low": self.low, "high": self.high, "n": self.n}

    @classmethod
    def from_json(cls, value: Any, source: str | None = None) -> BootstrapInterval:
        """Read ``{"low", "high", "n"}``; ZendarError naming every missing or wrong member."""
        return _checked(cls._read, value, "bootstrap", source)

    @classmethod
    def _read(cls, value: Any, where: str, problems: list[str]) -> BootstrapInterval:
        if not _object(value, where, ("low", "high", "n"), (), problems):
            return cls(None, None, 0)
        low = _member(value, "low", where, _fraction, problems)
        high = _member(value, "high", where, _fraction, problems)
        if "low" in value and "high" in value and (value["low"] is None) != (value["high"] is None):
            problems.append(f"{where}: expected 'low' and 'high' both numbers or both null")
        return cls(low, high, _member(value, "n", where, _count, problems, 0))


_CURVE_KEYS = ("recall", "precision", "precision_envelope", "score")


@dataclass(frozen=True)
class PRCurve:
    """One band's precision-recall curve as ``metrics.json`` keeps it (thinned past 10,000 points).

    Attributes
    ----------
    recall, precision, precision_envelope, score : tuple of float
        One point per distinct score, descending: recall, measured precision, its envelope (what
        the AP integrates) and the score; all four of one length, empty without detections.
    """

    recall: tuple[float, ...]
    precision: tuple[float, ...]
    precision_envelope: tuple[float, ...]
    score: tuple[float, ...]

    def to_json(self) -> dict[str, list[float]]:
        """``{"recall": [...], "precision": [...], "precision_envelope": [...], "score": [...]}``."""
        return {
            "recall": list(self.recall),
            "precision": list(self.precision),
            "precision_envelope": list(self.precision_envelope),
            "score": list(self.score),
        }

    @classmethod
    def from_json(cls, value: Any, source: str | None = None) -> PRCurve:
        """Read the four lists; ZendarError naming every missing or wrong member."""
        return _checked(cls._read, value, "pr_curve", source)

    @classmethod
    def _read(cls, value: Any, where: str, problems: list[str]) -> PRCurve:
        if not _object(value, where, _CURVE_KEYS, (), problems):
            return cls((), (), (), ())
        columns = [_member(value, key, where, _numbers, problems, ()) for key in _CURVE_KEYS]
        if len({len(value[key]) for key in _CURVE_KEYS if isinstance(value.get(key), list)}) > 1:
            problems.append(f"{where}: expected {', '.join(_CURVE_KEYS)} of one length")
        return cls(*columns)


_METRICS_REQUIRED = (
    "ap", "counts", "protocol", "partial", "n_frames", "n_frames_ground_truth", "n_scenes", "n_predictions", "meta",
)
_METRICS_OPTIONAL = ("pr_curves", "bootstrap", "split")


@dataclass(frozen=True)
class MetricsRecord:
    """Everything one evaluation produced: the typed form of ``metrics.json``.

    Attributes
    ----------
    ap : mapping of str to float or None
        Band → AP in [0, 1], None for a band without ground truth.
    counts : mapping of str to BandCounts
        Band → ground truths, true and false positives.
    protocol : mapping
        The protocol the scores were computed under (:func:`~zendar_dataset.eval.protocol_dict`).
    partial : bool
        Only the ground-truth frames present in the predictions were evaluated.
    n_frames, n_frames_ground_truth, n_scenes, n_predictions : int
        Frames and scenes evaluated, frames in the ground truth, predictions scored.
    meta : mapping
        The predictions' ``meta`` object.
    pr_curves : mapping of str to PRCurve, or None
        Band → precision-recall curve (always present in what the evaluator writes).
    bootstrap : mapping of str to BootstrapInterval, or None
        Band → 95% interval, when resampling was asked for.
    split : str or None
        The ground truth's split, when known.

    Examples
    --------
    >>> from zendar_dataset.eval import evaluate
    >>> gt = {"frames": {"s/1": [{"x": 10.0, "y": 0.0}]}}
    >>> preds = {"meta": {"method": "demo"}, "results": {"s/1": [{"x": 11.0, "y": 0.0, "score": 0.9}]}}
    >>> metrics = evaluate(preds, gt)
    >>> record = MetricsRecord.from_json(metrics)
    >>> record.ap["near"], record.counts["near"].tp, record.to_json() == metrics
    (1.0, 1, True)
    """

    ap: Mapping[str, float | None]
    counts: Mapping[str, BandCounts]
    protocol: Mapping[str, Any]
    partial: bool
    n_frames: int
    n_frames_ground_truth: int
    n_scenes: int
    n_predictions: int
    meta: Mapping[str, Any]
    pr_curves: Mapping[str, PRCurve] | None = None
    bootstrap: Mapping[str, BootstrapInterval] | None = None
    split: str | None = None

    def to_json(self) -> dict[str, Any]:
        """The ``metrics.json`` structure, members in the order the evaluator writes them."""
        document: dict[str, Any] = {
            "ap": {band: self.ap[band] for band in BAND_NAMES},
            "counts": {band: self.counts[band].to_json() for band in BAND_NAMES},
        }
        if self.pr_curves is not None:
            document["pr_curves"] = {band: self.pr_curves[band].to_json() for band in BAND_NAMES}
        document["protocol"] = copy.deepcopy(dict(self.protocol))
        document["partial"] = self.partial
        document["n_frames"] = self.n_frames
        document["n_frames_ground_truth"] = self.n_frames_ground_truth
        document["n_scenes"] = self.n_scenes
        document["n_predictions"] = self.n_predictions
        if self.bootstrap is not None:
            document["bootstrap"] = {band: self.bootstrap[band].to_json() for band in BAND_NAMES}
        if self.split is not None:
            document["split"] = self.split
        document["meta"] = copy.deepcopy(dict(self.meta))
        return document

    @classmethod
    def from_json(cls, value: Any, source: str | None = None) -> MetricsRecord:
        """Read what :func:`~zendar_dataset.eval.evaluate` returns or ``metrics.json`` holds.

        Parameters
        ----------
        value
            The parsed JSON object.
        source
            Where it came from (a file name), put before every problem.

        Raises
        ------
        ZendarError
            Naming every missing, unexpected or wrong member (``problems`` lists them one each),
            including a per-band object without one of the protocol's bands.
        """
        return _checked(cls._read, value, "metrics", source)

    @classmethod
    def _read(cls, value: Any, where: str, problems: list[str]) -> MetricsRecord:
        if not _object(value, where, _METRICS_REQUIRED, _METRICS_OPTIONAL, problems):
            return cls({}, {}, {}, False, 0, 0, 0, 0, {})
        return cls(
            ap=_member(value, "ap", where, functools.partial(_by_band, _fraction), problems, {}),
            counts=_member(value, "counts", where, functools.partial(_by_band, BandCounts._read), problems, {}),
            protocol=_member(value, "protocol", where, _mapping, problems, {}),
            partial=_member(value, "partial", where, _flag, problems, False),
            n_frames=_member(value, "n_frames", where, _count, problems, 0),
            n_frames_ground_truth=_member(value, "n_frames_ground_truth", where, _count, problems, 0),
            n_scenes=_member(value, "n_scenes", where, _count, problems, 0),
            n_predictions=_member(value, "n_predictions", where, _count, problems, 0),
            meta=_member(value, "meta", where, _mapping, problems, {}),
            pr_curves=_member(value, "pr_curves", where, functools.partial(_by_band, PRCurve._read), problems),
            bootstrap=_member(value, "bootstrap", where, functools.partial(_by_band, BootstrapInterval._read), problems),
            split=_member(value, "split", where, _text, problems),
        )


def as_metrics_record(metrics: MetricsRecord | Mapping[str, Any]) -> MetricsRecord:
    """``metrics`` itself when it is a record, else ``MetricsRecord.from_json(metrics)``."""
    return metrics if isinstance(metrics, MetricsRecord) else MetricsRecord.from_json(metrics)
