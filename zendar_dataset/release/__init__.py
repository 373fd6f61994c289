"""Reading the original Zendar release (2020 ``.pbs`` protobuf streams) and importing it into format v1.

- :func:`iter_messages` / :class:`ReleaseStream`: one stream file, framing, kind and schema
  generation detected (``stream.py``, ``messages.py``, ``wire.py``).
- :func:`import_release`: a release folder into a format-v1 dataset (``importer.py``), reported in an
  :class:`ImportSummary` (``summary.py``).

See docs/release.md.
"""

from zendar_dataset.release.importer import import_release
from zendar_dataset.release.stream import Framing, Loss, ReleaseStream, iter_messages
from zendar_dataset.release.summary import ImportSummary

__all__ = ["Framing", "ImportSummary", "Loss", "ReleaseStream", "import_release", "iter_messages"]
