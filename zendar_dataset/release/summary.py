"""The import summary: what happened to every stream of every scene, and what was assumed.

Printed by ``zendar-data import-release`` (:meth:`ImportSummary.lines`) and saved
as ``release_import.json`` in the dataset root (:meth:`ImportSummary.to_json`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

SUMMARY_JSON = "release_import.json"


@dataclass
class StreamSummary:
    """What happened to one stream file."""

    path: str
    kind: str | None = None
    framing: str | None = None
    records: int = 0
    empty_records: int = 0
    written_to: str | None = None
    skipped: list[str] = field(default_factory=list)
    lost_bytes: int = 0
    notes: list[str] = field(default_factory=list)
    unknown_fields: dict[str, int] = field(default_factory=dict)  # "<Message>.<number>" -> occurrences ignored


@dataclass
class SceneSummary:
    """One scene: where it went, its streams and the assumptions made."""

    scene_id: str
    source: str
    status: str = "imported"  # or "already imported"
    fingerprint: str | None = None  # of the source streams' content (release/discover.py)
    streams: list[StreamSummary] = field(default_factory=list)
    assumptions: list[str] = field(default_factory=list)


@dataclass
class ImportSummary:
    """The whole import, printable with :meth:`lines` and saved as ``release_import.json``."""

    source: str
    out: str
    scenes: list[SceneSummary] = field(default_factory=list)

    def lines(self) -> list[str]:
        """The summary as printed: a totals line, then per scene its streams and assumptions."""
        out = []
        n_streams = sum(len(s.streams) for s in self.scenes)
        n_records = sum(st.records for s in self.scenes for st in s.streams)
        out.append(f"{self.source}: {len(self.scenes)} scenes, {n_streams} streams, {n_records} records read -> {self.out}")
        for scene in self.scenes:
            out.append(f"scene {scene.scene_id} ({scene.status}) from {scene.source}")
            for st in scene.streams:
                target = f" -> {st.written_to}" if st.written_to else ""
                out.append(f"  {st.path}: {st.kind or '?'}, {st.records} records{target}; framing {st.framing}")
                for note in st.notes:
                    out.append(f"    kind: {note}")
                if st.empty_records:
                    out.append(f"    {st.empty_records} empty records (length 0) skipped")
                if st.unknown_fields:
                    counts = ", ".join(f"{name} x{n}" for name, n in st.unknown_fields.items())
                    out.append(f"    unknown fields (not in the SDK's definition) ignored: {counts}")
                if st.lost_bytes:
                    out.append(f"    lost {st.lost_bytes} bytes to --skip-corrupt")
                for reason in st.skipped:
                    out.append(f"    skipped: {reason}")
            for assumption in scene.assumptions:
                out.append(f"  assumed: {assumption}")
        return out

    def to_json(self) -> dict:
        """The summary as the JSON document of ``release_import.json``."""
        return asdict(self)
