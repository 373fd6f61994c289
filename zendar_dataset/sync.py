"""The synchronisation index: which element of every stream goes with each reference frame.

All streams are stamped by one GPS clock (int64 ns). For each reference frame a
stream contributes either

* its **nearest** element within a tolerance (the indices of ``pandas.merge_asof``,
  ``direction="nearest"``; ``|Δt| <= tolerance`` is inclusive, ties go to the
  earlier element), or
* for windowed streams (radar cubes), the **K latest** elements with
  ``timestamp_ns <= reference``; the window is filled when K such elements
  exist and the latest is within the tolerance of the reference.

Δt is always ``element − reference`` in ns (for a window: its latest element).
Default tolerances: half the stream's median frame interval for nearest
matching (so no element serves two neighbouring frames of a same-rate stream),
1.5 median intervals for windows (the latest element at or before the
reference of a gapless stream is within one interval; the extra half absorbs
capture jitter, while a missing element, a gap of two intervals, still shows).
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from zendar_dataset.errors import ZendarFormatError

MISSING = -1

#: Largest tolerance in ms (about 285 years): its ns still fit int64, the type of every timestamp.
MAX_TOLERANCE_MS = 9e12

TOLERANCE_HELP = (
    "tolerance_ms is a number (milliseconds, all streams) or a dict keyed by "
    "'<group>/<sensor>' or '<group>'"
)


@dataclass(frozen=True)
class StreamTimes:
    """One stream's timestamps as seen by the index.

    Attributes
    ----------
    name
        ``"<group>/<sensor>"`` (``"tracklog"`` and ``"labels"`` have no sensor part).
    timestamp_ns
        ``[N]`` int64 GPS ns, strictly increasing.
    window
        0 for nearest matching, ``K >= 1`` for the K latest elements at or before the reference.
    interpolated
        The stream is interpolated at the reference time (the tracklog): it is present
        wherever the reference lies inside its span, and Δt is the nearest sample's.
        Tolerances do not apply to it.
    """

    name: str
    timestamp_ns: np.ndarray
    window: int = 0
    interpolated: bool = False

    def __post_init__(self) -> None:
        t = np.asarray(self.timestamp_ns)
        if t.ndim != 1 or not np.issubdtype(t.dtype, np.integer):
            raise ZendarFormatError(
                f"{self.name}: timestamp_ns must be a 1-D int64 array, got {t.dtype} {list(t.shape)}"
            )
        if t.size > 1:
            # One byte per element (a fresh int64 diff of an hour's tracklog costs more than the index).
            not_after = t[1:] <= t[:-1]
            if not_after.any():
                k = int(np.argmax(not_after))
                raise ZendarFormatError(
                    f"{self.name}/timestamp_ns: must be strictly increasing; element {k + 1} "
                    f"({int(t[k + 1])}) does not follow element {k} ({int(t[k])})"
                )
        if self.window < 0:
            raise ValueError(f"{self.name}: window must be >= 0, got {self.window}")
        if self.window and self.interpolated:
            raise ValueError(f"{self.name}: a stream is either windowed or interpolated")
        object.__setattr__(self, "timestamp_ns", t.astype(np.int64, copy=False))

    @functools.cached_property
    def median_interval_ns(self) -> int | None:
        """Median spacing in ns, or None with fewer than two elements; computed once per stream."""
        return median_interval_ns(self.timestamp_ns)


def median_interval_ns(timestamp_ns: np.ndarray) -> int | None:
    """Median spacing of a stream in ns (``int(np.median(np.diff(t)))``), or None with fewer than two elements."""
    # Imported here: numba is paid for by the first index built, not by every import of the package.
    from zendar_dataset.interval_median import median_interval_ns as compiled

    return compiled(timestamp_ns)


def resolve_tolerances_ns(
    streams: Sequence[StreamTimes],
    tolerance_ms: float | Mapping[str, float] | None,
    reference_ns: np.ndarray,
) -> dict[str, int]:
    """Per-stream tolerance in ns from the user's ``tolerance_ms`` and the defaults.

    Raises
    ------
    ValueError
        For a tolerance that is negative, not finite or above :data:`MAX_TOLERANCE_MS`, or a dict
        key that names no stream (a typo would otherwise silently fall back to the default).
    """
    names = [s.name for s in streams if not s.interpolated]
    groups = {name.split("/", 1)[0] for name in names}
    if isinstance(tolerance_ms, Mapping):
        unknown = sorted(k for k in tolerance_ms if k not in names and k not in groups)
        if unknown:
            raise ValueError(
                f"tolerance_ms names streams {unknown} that are not matched by tolerance here; "
                f"known: {sorted(set(names) | groups)} (the tracklog is interpolated, not matched)"
            )
        values = list(tolerance_ms.values())
    elif tolerance_ms is None:
        values = []
    elif isinstance(tolerance_ms, (int, float)) and not isinstance(tolerance_ms, bool):
        values = [tolerance_ms]
    else:
        raise ValueError(f"{TOLERANCE_HELP}; got {tolerance_ms!r}")
    for value in values:
        # inf, or a value whose ns do not fit int64, would overflow when rounded to ns below.
        if (not isinstance(value, (int, float)) or isinstance(value, bool)
                or not 0 <= value <= MAX_TOLERANCE_MS):
            raise ValueError(
                f"tolerances must be non-negative, finite numbers of ms up to {MAX_TOLERANCE_MS:g}, got {value!r}"
            )

    tolerances: dict[str, int] = {}
    for stream in streams:
        if stream.interpolated:
            continue
        chosen: float | None = None
        if isinstance(tolerance_ms, Mapping):
            group = stream.name.split("/", 1)[0]
            chosen = tolerance_ms.get(stream.name, tolerance_ms.get(group))
        elif tolerance_ms is not None:
            chosen = tolerance_ms
        if chosen is not None:
            tolerances[stream.name] = int(round(float(chosen) * 1e6))
            continue
        interval = stream.median_interval_ns
        if interval is None:  # one element or none: the reference's spacing stands in
            interval = median_interval_ns(reference_ns) or 0
        tolerances[stream.name] = (3 * interval) // 2 if stream.window else interval // 2
    return tolerances


def _nearest(reference_ns: np.ndarray, stream_ns: np.ndarray, tolerance_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """Index of the nearest stream element within tolerance per reference time (or MISSING) and its Δt.

    ``pandas.merge_asof(direction="nearest", tolerance=...)`` gives these indices (the tests check
    it), but builds two DataFrames and a float column per call: 18 ms of a 1-hour scene's 20 ms index
    (benchmarks/bench_sync.py). The stream is sorted and unique (:class:`StreamTimes`), so the
    candidates are the elements either side of each reference time; the earlier wins a tie.
    Δt is ``element − reference`` in ns, 0 where MISSING.
    """
    if stream_ns.size == 0:
        return np.full(reference_ns.shape, MISSING, dtype=np.int64), np.zeros(reference_ns.shape, dtype=np.int64)
    after = np.searchsorted(stream_ns, reference_ns, side="left")
    if stream_ns.size == 1:
        after[:] = 0
        index, dt_ns = after, stream_ns[0] - reference_ns
    else:
        np.clip(after, 1, stream_ns.size - 1, out=after)
        before = after - 1
        to_before = reference_ns - stream_ns[before]  # negative only before the stream's first element
        dt_ns = stream_ns[after] - reference_ns  # negative only after its last
        take_before = to_before <= dt_ns
        # np.where, not a masked copyto / negative: the masked ufunc loops took a third of the call.
        index = np.where(take_before, before, after)
        dt_ns = np.where(take_before, -to_before, dt_ns)
    far = np.abs(dt_ns) > tolerance_ns
    index[far] = MISSING
    dt_ns[far] = 0
    return index, dt_ns


def _inside_span(reference_ns: np.ndarray, stream_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest sample (any distance) where the reference lies inside the stream's span (else MISSING) and its Δt."""
    if stream_ns.size == 0:
        return _nearest(reference_ns, stream_ns, 0)
    index, dt_ns = _nearest(reference_ns, stream_ns, int(stream_ns[-1] - stream_ns[0]) + 1)
    outside = (reference_ns < stream_ns[0]) | (reference_ns > stream_ns[-1])
    np.copyto(index, MISSING, where=outside)
    np.copyto(dt_ns, 0, where=outside)
    return index, dt_ns


def latest_at_or_before(stream_ns: np.ndarray, reference_ns: np.ndarray | int) -> np.ndarray:
    """The loader's rule for windowed streams: the latest element at or before each reference time.

    Parameters
    ----------
    stream_ns : numpy.ndarray
        ``[N]`` int64 sorted stream timestamps.
    reference_ns : numpy.ndarray or int
        Reference timestamps (any shape) or one timestamp.

    Returns
    -------
    numpy.ndarray
        int64 indices into ``stream_ns``, shaped like ``reference_ns``; -1 where no element is at or
        before the reference.
    """
    return (np.searchsorted(stream_ns, reference_ns, side="right") - 1).astype(np.int64)


def _latest(
    reference_ns: np.ndarray, stream_ns: np.ndarray, window: int, tolerance_ns: int
) -> tuple[np.ndarray, np.ndarray]:
    """Index of the latest element of a filled window per reference time (or MISSING) and its Δt (0 where MISSING)."""
    last = latest_at_or_before(stream_ns, reference_ns)
    if stream_ns.size == 0:
        return np.full(reference_ns.shape, MISSING, dtype=np.int64), np.zeros(reference_ns.shape, dtype=np.int64)
    dt_ns = stream_ns[np.clip(last, 0, None)] - reference_ns
    unfilled = (last < window - 1) | (-dt_ns > tolerance_ns)
    np.copyto(last, MISSING, where=unfilled)
    np.copyto(dt_ns, 0, where=unfilled)
    return last, dt_ns


class SyncReport(pd.DataFrame):
    """Residuals and drops per scene and stream: a DataFrame whose ``print`` is a summary.

    All columns stay in the frame (``report.columns``, ``report.to_string()``,
    filtering, ``set_index`` …; derived frames are plain DataFrames).  ``str()``
    shows the columns a reader checks first, with residuals in milliseconds,
    instead of pandas' width-truncated table that cuts the stream names away.
    """

    @property
    def _constructor(self):
        return pd.DataFrame

    def summary(self) -> str:
        """One line per scene and stream: kept items, matched, missing, dropped, median and max |Δt| in ms."""
        if self.empty:
            return "sync report: no scenes"
        view = pd.DataFrame(
            {
                "scene_id": self["scene_id"],
                "stream": self["stream"],
                "items": pd.to_numeric(self["items"], errors="coerce").astype("Int64"),
                "matched": pd.to_numeric(self["matched"], errors="coerce").astype("Int64"),
                "missing": pd.to_numeric(self["missing"], errors="coerce").astype("Int64"),
                "dropped": pd.to_numeric(self["dropped"], errors="coerce").astype("Int64"),
                "median|dt|_ms": pd.to_numeric(self["abs_dt_median_ns"], errors="coerce") / 1e6,
                "max|dt|_ms": pd.to_numeric(self["abs_dt_max_ns"], errors="coerce") / 1e6,
            }
        )
        references = sorted(set(self["reference"].astype(str)))
        n_scenes = self["scene_id"].nunique()
        header = (
            f"sync report: {n_scenes} scene{'' if n_scenes == 1 else 's'}, reference {', '.join(references)}, "
            "dt = element - reference"
        )
        table = view.to_string(index=False, float_format=lambda v: f"{v:.3f}", na_rep="-")
        return f"{header}\n{table}\n(a DataFrame of {len(self.columns)} columns: report.to_string() shows them all)"

    def __str__(self) -> str:
        return self.summary()


@dataclass
class SyncTable:
    """The synchronisation index of one scene: one row per kept reference frame.

    Attributes
    ----------
    reference
        Name of the reference stream.
    reference_index
        ``[N]`` int64 index of each kept frame in the reference stream.
    timestamp_ns
        ``[N]`` int64 reference times.
    element
        Per stream ``[N]`` int64 index of the matched element (for a window: its
        latest element; the window is ``element - K + 1 .. element``), ``-1`` if none.
    dt_ns
        Per stream ``[N]`` int64 ``element time − reference time``; 0 where ``element == -1``.
    tolerance_ns
        Per stream tolerance that was applied (absent for interpolated streams).
    window
        Per stream window length (0 = nearest).
    dropped
        Per stream, how many reference frames were left out because this stream
        missed (required stream absent, or window not filled). A frame missing two
        streams counts for both.
    dropped_total
        Reference frames left out for any reason.
    """

    reference: str
    reference_index: np.ndarray
    timestamp_ns: np.ndarray
    element: dict[str, np.ndarray]
    dt_ns: dict[str, np.ndarray]
    tolerance_ns: dict[str, int]
    window: dict[str, int]
    dropped: dict[str, int]
    dropped_total: int
    n_reference: int = field(default=0)

    def __len__(self) -> int:
        return int(self.reference_index.size)

    @property
    def streams(self) -> list[str]:
        return list(self.element)

    def to_frame(self) -> pd.DataFrame:
        """The index as a DataFrame: ``reference_index``, ``timestamp_ns`` and per stream
        ``<stream>:element`` (nullable Int64) and ``<stream>:dt_ns`` (nullable Int64)."""
        columns: dict[str, object] = {
            "reference_index": self.reference_index,
            "timestamp_ns": self.timestamp_ns,
        }
        for name in self.element:
            missing = self.element[name] == MISSING
            columns[f"{name}:element"] = pd.array(
                np.where(missing, 0, self.element[name]), dtype="Int64"
            )
            columns[f"{name}:element"][missing] = pd.NA
            dt = pd.array(self.dt_ns[name], dtype="Int64")
            dt[missing] = pd.NA
            columns[f"{name}:dt_ns"] = dt
        return pd.DataFrame(columns)

    def residual_stats(self) -> pd.DataFrame:
        """Per stream: tolerance, window, matched/missing/dropped counts and Δt statistics (ns)."""
        rows = []
        for name in self.element:
            present = self.element[name] != MISSING
            dt = self.dt_ns[name][present]
            abs_dt = np.abs(dt)
            rows.append(
                {
                    "stream": name,
                    "window": self.window[name],
                    "tolerance_ms": self.tolerance_ns[name] / 1e6 if name in self.tolerance_ns else np.nan,
                    "items": len(self),
                    "matched": int(present.sum()),
                    "missing": int((~present).sum()),
                    "dropped": self.dropped[name],
                    "dt_mean_ns": float(dt.mean()) if dt.size else np.nan,
                    "dt_min_ns": int(dt.min()) if dt.size else pd.NA,
                    "dt_max_ns": int(dt.max()) if dt.size else pd.NA,
                    "abs_dt_median_ns": float(np.median(abs_dt)) if dt.size else np.nan,
                    "abs_dt_p95_ns": float(np.percentile(abs_dt, 95)) if dt.size else np.nan,
                    "abs_dt_max_ns": int(abs_dt.max()) if dt.size else pd.NA,
                }
            )
        return pd.DataFrame(rows)


def build_sync_table(
    reference: StreamTimes,
    streams: Iterable[StreamTimes],
    tolerance_ms: float | Mapping[str, float] | None = None,
    require: Iterable[str] = (),
    keep_unfilled_windows: bool = False,
    absent_groups: Iterable[str] = (),
) -> SyncTable:
    """Match every stream to every reference frame.

    Parameters
    ----------
    reference
        The reference stream (one item per element).
    streams
        The other streams; windowed ones have ``window >= 1``.
    tolerance_ms
        None for the defaults, a number for every stream, or a dict keyed by
        ``"<group>/<sensor>"`` or ``"<group>"`` (unmentioned streams keep defaults).
    require
        Stream names (``"<group>/<sensor>"``) or groups whose absence drops a frame.
    keep_unfilled_windows
        Keep frames whose window cannot be filled (the stream is then missing for
        them) instead of dropping them.
    absent_groups
        Requested groups with no stream in this scene; requiring one drops every
        frame (counted under the group's name).

    Returns
    -------
    SyncTable
    """
    streams = list(streams)
    names = [s.name for s in streams]
    if len(set(names)) != len(names):
        raise ValueError(f"stream names must be unique, got {names}")
    reference_ns = reference.timestamp_ns
    tolerances = resolve_tolerances_ns(streams, tolerance_ms, reference_ns)

    required: set[str] = set()
    groups = {name.split("/", 1)[0] for name in names}
    absent_groups = set(absent_groups)
    absent_required = []
    for key in require:
        if key in absent_groups:
            absent_required.append(key)
        elif key in names:
            required.add(key)
        elif key in groups:
            required.update(n for n in names if n.split("/", 1)[0] == key)
        else:
            raise ValueError(f"require names unknown stream {key!r}; known: {sorted(set(names) | groups)}")

    element: dict[str, np.ndarray] = {}
    dt_ns: dict[str, np.ndarray] = {}
    keep = np.ones(reference_ns.shape, dtype=bool)
    lacking: dict[str, np.ndarray] = {}
    for stream in streams:
        if stream.interpolated:
            idx, dt = _inside_span(reference_ns, stream.timestamp_ns)
        elif stream.window:
            idx, dt = _latest(reference_ns, stream.timestamp_ns, stream.window, tolerances[stream.name])
        else:
            idx, dt = _nearest(reference_ns, stream.timestamp_ns, tolerances[stream.name])
        element[stream.name] = idx
        dt_ns[stream.name] = dt
        must_have = stream.name in required or (stream.window and not keep_unfilled_windows)
        if must_have:
            lacking[stream.name] = idx == MISSING
            keep &= idx != MISSING

    dropped = {name: 0 for name in names}
    for name, miss in lacking.items():
        dropped[name] = int(miss.sum())
    for group in absent_required:
        keep[:] = False
        dropped[group] = int(reference_ns.size)

    kept = np.flatnonzero(keep)
    every_frame_kept = kept.size == reference_ns.size
    kept_ns = reference_ns if every_frame_kept else reference_ns[kept]
    if not every_frame_kept:
        for name in names:
            element[name] = element[name][kept]
            dt_ns[name] = dt_ns[name][kept]
    return SyncTable(
        reference=reference.name,
        reference_index=kept.astype(np.int64),
        timestamp_ns=kept_ns,
        element=element,
        dt_ns=dt_ns,
        tolerance_ns=tolerances,
        window={s.name: s.window for s in streams},
        dropped=dropped,
        dropped_total=int(reference_ns.size - kept.size),
        n_reference=int(reference_ns.size),
    )


# -- from a scene store --------------------------------------------------------

STREAM_GROUPS = ("radar", "sar", "camera", "lidar", "tracklog", "labels")
SENSOR_GROUPS = ("radar", "sar", "camera", "lidar")


def resolve_reference(reader, reference: str) -> str:
    """The reference stream of a scene: ``"sar"`` is its first SAR sensor in name order,
    ``"<group>/<sensor>"`` a given one (any sensor stream, or ``"tracklog"``)."""
    scene = reader.scene_id
    if reference == "tracklog":
        if "tracklog" not in reader.streams:
            raise ZendarFormatError(f"{scene}: reference 'tracklog': the scene has no tracklog")
        return reference
    group, _, sensor = reference.partition("/")
    if group not in SENSOR_GROUPS:
        raise ValueError(
            f"reference must be 'sar', 'sar/<name>', another '<group>[/<sensor>]' of {SENSOR_GROUPS} "
            f"or 'tracklog'; got {reference!r}"
        )
    sensors = reader.sensors(group)
    if not sensor:
        if not sensors:
            raise ZendarFormatError(f"{scene}: reference {reference!r}: the scene has no {group} stream")
        return f"{group}/{sensors[0]}"
    if sensor not in sensors:
        raise ZendarFormatError(
            f"{scene}: reference {reference!r}: no such stream; the scene's {group} sensors are {sensors}"
        )
    return reference


def scene_stream_names(reader, streams: Iterable[str]) -> tuple[list[str], list[str]]:
    """Expand requested groups/streams into this scene's stream names.

    Returns ``(names, absent_groups)``: ``"tracklog"`` and ``"labels"`` always appear
    (empty when the scene lacks them); a sensor group with no sensor in the scene is absent.
    """
    names: list[str] = []
    absent: list[str] = []
    for key in streams:
        group, _, sensor = key.partition("/")
        if group in ("tracklog", "labels"):
            names.append(group)
        elif sensor:
            if sensor not in reader.sensors(group):
                raise ZendarFormatError(
                    f"{reader.scene_id}: stream {key!r} not found; the scene's {group} sensors are "
                    f"{reader.sensors(group)}"
                )
            names.append(key)
        else:
            found = [f"{group}/{s}" for s in reader.sensors(group)]
            if not found:
                absent.append(group)
            names.extend(found)
    return list(dict.fromkeys(names)), absent


def scene_sync_table(
    reader,
    streams: Iterable[str],
    reference: str = "sar",
    cube_window: int = 1,
    tolerance_ms: float | Mapping[str, float] | None = None,
    require: Iterable[str] = (),
    keep_unfilled_windows: bool = False,
) -> SyncTable:
    """The synchronisation index of one scene read through a ``SceneReader``.

    Reads only timestamp arrays. Label frames are the scene's first SAR stream's
    frames (format v1); the ``"labels"`` stream matches the nearest of them.
    """
    reference_name = resolve_reference(reader, reference)
    names, absent = scene_stream_names(reader, streams)
    timestamps = {}
    for name in names:
        if name == "labels":
            sar = reader.sensors("sar")
            has_labels = "labels/moving_cars" in reader.streams and sar
            timestamps[name] = reader.timestamps(f"sar/{sar[0]}") if has_labels else np.zeros(0, np.int64)
        elif name == "tracklog" and "tracklog" not in reader.streams:
            timestamps[name] = np.zeros(0, np.int64)
        else:
            timestamps[name] = reader.timestamps(name)
    stream_times = [
        StreamTimes(
            name,
            timestamps[name],
            window=cube_window if name.startswith("radar/") else 0,
            interpolated=name == "tracklog",
        )
        for name in names
    ]
    if isinstance(tolerance_ms, Mapping):
        # Keys were checked against the requested streams by the caller; a sensor
        # this scene lacks is simply not matched here.
        matched = {n for n in names if n != "tracklog"}
        matched |= {n.split("/", 1)[0] for n in matched}
        tolerance_ms = {k: v for k, v in tolerance_ms.items() if k in matched}
    return build_sync_table(
        StreamTimes(reference_name, reader.timestamps(reference_name)),
        stream_times,
        tolerance_ms=tolerance_ms,
        require=require,
        keep_unfilled_windows=keep_unfilled_windows,
        absent_groups=absent,
    )
