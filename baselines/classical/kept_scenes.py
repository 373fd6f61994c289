"""Scenes opened once for many passes over them, with what every pass of the chain reads.

A ``zendar-bench`` run passes over the same scenes once per CNN seed: the training windows, the
chain fit on the labelled and validation frames, the test scoring. Opening a scene checks all its
metadata (~30 ms on the demo config), and the SAR test reads every frame's image and takes its
median; both are the same for every seed. :class:`KeptScenes` keeps the open readers, ego poses and
SAR frames (with the magnitudes read) for the next pass, within a memory budget; results equal
reading the scenes afresh.
"""

from __future__ import annotations

import contextlib
import functools
import os
from collections.abc import Iterator
from typing import Any

import numpy as np

from zendar_dataset.format.reader import DatasetIndex, SceneReader
from zendar_dataset.geometry.frames import EgoPoses
from zendar_dataset.sar.frames import SarFrames

from zendar_baselines.fingerprints import dataset_index

#: Budget for what one :class:`KeptScenes` keeps between passes, counted as float32: every SAR image
#: of its scenes (and, with ``maps_too``, every radar cube, the size of its log-power maps). The demo
#: config's training and validation scenes take ~860 MB; the paper config's would not fit, and every
#: pass then opens and reads them again.
KEPT_SCENE_BYTES = 1 << 30


class KeptScene:
    """One open scene with what every pass over it reads: the reader, its ego poses and SAR frames
    (each read at first use), and ``maps``, arrays derived from the scene that the user keeps with it."""

    def __init__(self, reader: SceneReader, keep_all_frames: bool) -> None:
        self.reader = reader
        self.maps: dict[Any, np.ndarray] = {}
        self._keep_all_frames = keep_all_frames

    @functools.cached_property
    def poses(self) -> EgoPoses:
        return self.reader.ego_poses()

    @functools.cached_property
    def sar(self) -> SarFrames:
        """The scene's SAR frames; a kept scene keeps every magnitude read (:class:`SarFrames`)."""
        return SarFrames(self.reader, keep_frames=None) if self._keep_all_frames else SarFrames(self.reader)


class KeptScenes:
    """Scenes of a dataset, each opened once for many passes (a context manager; closes them on exit).

    Parameters
    ----------
    dataset : DatasetIndex, str or path
        The dataset (opened, or its root).
    scene_ids : list of str
        The scenes that may be kept: at the first :meth:`opened`, all of them are opened once and kept
        if their sizes fit :data:`KEPT_SCENE_BYTES` together (else closed again). Any other scene of
        the dataset is opened for its pass only.
    keep : bool
        Keep the scenes (within the budget); False opens every scene for its pass only.
    maps_too : bool
        Count the radar cubes' maps in the budget (a user that keeps maps in :attr:`KeptScene.maps`).
    """

    def __init__(self, dataset: DatasetIndex | str | os.PathLike, scene_ids: list[str], *, keep: bool = True,
                 maps_too: bool = False) -> None:
        self.index = dataset_index(dataset)
        self.keep = keep
        self._budget_ids = list(scene_ids)
        self._maps_too = maps_too
        self._checked = False
        self._scenes: dict[str, KeptScene] = {}
        self._stack = contextlib.ExitStack()

    def __enter__(self) -> KeptScenes:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Close every kept scene (a later pass opens them again)."""
        self._scenes.clear()
        self._stack.close()
        self._checked = False

    def _scene_bytes(self, reader: SceneReader) -> int:
        arrays = [f"sar/{s}/image" for s in reader.sensors("sar")]
        if self._maps_too:
            arrays += [f"radar/{r}/cube" for r in reader.sensors("radar")]
        return sum(4 * int(np.prod(reader.array(a).shape)) for a in arrays)

    def _keep_all_if_they_fit(self) -> None:
        """Open every scene of the budget once: kept if together they fit it, else closed again and
        ``keep`` turned off (each pass then opens its scenes)."""
        readers, total = {}, 0
        with contextlib.ExitStack() as opened:
            for scene_id in self._budget_ids:
                readers[scene_id] = opened.enter_context(self.index.open_scene(scene_id))
                total += self._scene_bytes(readers[scene_id])
                if total > KEPT_SCENE_BYTES:
                    self.keep = False
                    return  # the ``with`` closes them
            self._stack.enter_context(opened.pop_all())
        self._scenes = {scene_id: KeptScene(reader, keep_all_frames=True) for scene_id, reader in readers.items()}

    @contextlib.contextmanager
    def opened(self, scene_id: str) -> Iterator[KeptScene]:
        """The open scene: kept for later passes when ``keep``, it is one of ``scene_ids`` and they
        fit the budget; else opened for this ``with`` block only."""
        if scene_id in self._scenes:
            yield self._scenes[scene_id]
            return
        if self.keep and not self._checked:
            self._checked = True
            self._keep_all_if_they_fit()
            if scene_id in self._scenes:
                yield self._scenes[scene_id]
                return
        with self.index.open_scene(scene_id) as reader:
            yield KeptScene(reader, keep_all_frames=False)
