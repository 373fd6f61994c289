"""The ``autolabels`` step of ``zendar-bench`` (and ``zendar-bench autolabels``): the automatic masks of
a list of scenes in a mask store, one task per scene, in this process or on a Dask cluster.

A task (:func:`label_scene`) opens its scene, makes the automatic masks of every radar whose maps the
CFAR window fits (:func:`labelled_radars`), writes the scene's file into the store atomically (on
whichever host runs it: the store must be a directory every worker sees at the same path) and
returns the file's manifest entry, with the masks' quality against the manual labels when asked. Only this process writes the manifest (:meth:`MaskStore.record_scene`), in
the order the tasks finish; the masks do not depend on where or in which order they were made.
"""

from __future__ import annotations

import contextlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.cluster import DaskCluster, refuse_url_output
from zendar_dataset.errors import ZendarError
from zendar_dataset.format.reader import DatasetIndex, SceneReader
from zendar_dataset.output_location import other_entries, refuse_output_inside
from zendar_dataset.radar import FmcwParams, range_axis_m
from zendar_dataset.sar.frames import SarFrames
from zendar_dataset.temporary_files import owner_pid

from zendar_baselines.bench.steps import STORE_DIR, mask_parameters
from zendar_baselines.classical.cfar_baseline import cfar_misfits
from zendar_baselines.code_version import code_version
from zendar_baselines.fingerprints import dataset_index, dataset_location, dataset_on_worker, task_root
from zendar_baselines.labels.mask_store import MaskStore, RadarMasks, write_scene_file
from zendar_baselines.labels.masks import MaskParams, scene_masks
from zendar_baselines.labels.quality import QUALITY_REFERENCE, combine_quality, format_quality, mask_quality

QUALITY_FILE = "quality.json"


def _range_m(reader: SceneReader, radar: str, masks: np.ndarray) -> np.ndarray:
    n_range, n_doppler = masks.shape[1:]
    params = FmcwParams.from_calibration(reader.calibration.sensors[radar], n_samples=n_range, n_chirps=n_doppler)
    return range_axis_m(n_range, params.range_bin_m)


def _quality(reader: SceneReader, auto: RadarMasks) -> list[dict[str, Any]]:
    """Each radar's automatic masks against the scene's CFAR-gated manual-label masks."""
    scores = []
    for radar, (_, auto_masks) in auto.items():
        _, label_masks = scene_masks(reader, radar, "labels", params=QUALITY_REFERENCE, progress=False)
        scores.append(mask_quality(auto_masks, label_masks, _range_m(reader, radar, auto_masks)))
    return scores


@dataclass(frozen=True)
class AutoLabelTask:
    """One scene to label (picklable: it travels to a worker process or a Dask worker).

    Attributes
    ----------
    root : str
        The dataset's root (a path every worker sees, or an fsspec URL).
    storage_options : dict
        The dataset's fsspec options.
    scene_id : str
    store_dir : pathlib.Path
        The mask store's directory.
    quality : bool
        Also measure the masks against the scene's manual labels.
    params : MaskParams
        The automatic labels' settings.
    """

    root: str
    storage_options: dict = field(hash=False)
    scene_id: str
    store_dir: Path
    quality: bool
    params: MaskParams


@dataclass(frozen=True)
class LabelledScene:
    """What a task returns: the scene file's manifest entry and, with quality, one result per radar."""

    entry: dict[str, Any]
    scores: list[dict[str, Any]]


def labelled_radars(reader: SceneReader) -> list[str]:
    """The radars of one open scene that get automatic masks: those whose maps the CFAR window fits
    (the automatic labels start from CFAR peaks; :func:`~zendar_baselines.classical.cfar_baseline.cfar_misfits`).

    Raises
    ------
    ZendarError
        When there is none, saying why.
    """
    misfits = cfar_misfits(reader)
    radars = [radar for radar in reader.sensors("radar") if radar not in misfits]
    if not radars:
        why = "; ".join(f"radar {radar}: {reason}" for radar, reason in misfits.items()) or "no range-Doppler cubes"
        raise ZendarError(f"scene {reader.scene_id}: no radar to label automatically: {why}")
    return radars


def label_scene(task: AutoLabelTask) -> LabelledScene:
    """Make, write and (optionally) measure one scene's automatic masks (module docstring).

    Raises
    ------
    ZendarError
        When this host cannot read the dataset (naming the host), the scene has no radar to label
        (:func:`labelled_radars`), or no labels to measure against.
    """
    index = dataset_on_worker(task.root, task.storage_options, task.scene_id)
    with index.open_scene(task.scene_id) as reader:
        radars = labelled_radars(reader)
        sar = SarFrames(reader)
        auto = {radar: scene_masks(reader, radar, "auto", sar=sar, params=task.params, progress=False) for radar in radars}
        entry = write_scene_file(task.store_dir, task.scene_id, auto)
        return LabelledScene(entry, _quality(reader, auto) if task.quality else [])


def write_auto_labels(dataset: DatasetIndex | str | os.PathLike, scene_ids: list[str], out_dir: Path, *,
                      quality: bool = True, cluster: DaskCluster | None = None,
                      params: MaskParams | None = None) -> dict[str, Any] | None:
    """Automatic masks of ``scene_ids`` (a mask store in ``out_dir / "store"``) and their quality.

    With ``quality``, every scene's masks are also measured against its manual-label masks and the
    pooled figures are written to ``out_dir / "quality.json"`` (and returned). They describe the
    labels, feed no model and choose nothing, so they may read the manual labels of any scene. The
    reference is :data:`zendar_baselines.labels.quality.QUALITY_REFERENCE` (CFAR-gated masks).

    Parameters
    ----------
    dataset
        The dataset root, or the dataset already opened.
    scene_ids
        The scenes to label; those already in the store (same parameters and code) are kept.
    out_dir
        Where the store and ``quality.json`` go.
    quality
        Measure the masks against the manual labels.
    cluster
        A connected Dask cluster: the scenes to label are one task each on its workers (``out_dir``
        must be a directory they all see; checked). Without one, they are labelled in this process.
    params
        The automatic labels' settings (default :class:`MaskParams`), recorded in the store.

    Raises
    ------
    ZendarError
        For ``quality`` on a scene without labels, a store of another dataset in ``out_dir``, an
        ``out_dir`` some worker does not see, or a scene whose workers died.
    """
    index = dataset_index(dataset)
    params = MaskParams() if params is None else params
    parameters = mask_parameters(params)
    if cluster is not None:
        refuse_url_output(out_dir, "the automatic labels")
    store = MaskStore.create(out_dir / STORE_DIR, index, parameters, code_version=code_version())
    root = task_root(index)
    store_dir = Path(store.directory).absolute()
    scores: list[dict[str, Any]] = []
    todo = []
    with tqdm(total=len(scene_ids), desc="automatic labels", unit="scene") as bar:
        for scene_id in sorted(scene_ids):
            if not store.has_scene(scene_id, parameters, code_version()):
                todo.append(AutoLabelTask(root, dict(index.storage_options), scene_id, store_dir, quality, params))
                continue
            if quality:
                with index.open_scene(scene_id) as reader:
                    scores += _quality(reader, store.scene(scene_id))
            bar.update()

        def done(task: AutoLabelTask, labelled: LabelledScene) -> None:
            store.record_scene(task.scene_id, labelled.entry)
            scores.extend(labelled.scores)
            bar.update()

        if cluster is None:
            for task in todo:
                done(task, label_scene(task))
        elif todo:
            cluster.remove_orphaned_temporaries(store_dir)
            with cluster.shared_directory(store_dir) as shared:
                cluster.run(label_scene, todo, shared=shared, on_done=done,
                            worker_died=lambda task: ZendarError(
                                f"{task.scene_id}: the Dask workers labelling it died (killed, out of memory, or their "
                                "node lost) as many times as the scheduler allows (distributed.scheduler.allowed-failures)"),
                            # Workers stopped mid-scene leave hidden temporaries, never a scene file at its final name.
                            on_interrupt=lambda: _remove_orphans(cluster, store_dir))
    if not quality:
        return None
    pooled = combine_quality(scores)
    document = {"quality": pooled, "table": format_quality(pooled)}
    write_json_atomic(out_dir / QUALITY_FILE, document)
    return document


def refuse_foreign_out(out_dir: Path, dataset: DatasetIndex | str | os.PathLike) -> None:
    """Refuse an ``--out`` of ``zendar-bench autolabels`` that is not new, empty, or its own output.

    Its own output is :data:`STORE_DIR` (whose content :meth:`MaskStore.create` judges), a
    :data:`QUALITY_FILE` it wrote and temporaries a killed run left; anything else is the user's
    and is never replaced, so a re-run into its own ``--out`` still resumes.

    Parameters
    ----------
    out_dir
        The ``--out`` directory.
    dataset
        The dataset labelled (its root or the dataset opened).

    Raises
    ------
    ZendarError
        When ``out_dir`` is inside the dataset, is not a directory, or holds files the command did not
        write (naming them); nothing is touched.
    """
    # First, so that an --out at or inside the dataset is named as such rather than by its files.
    refuse_output_inside(out_dir, datasets=(dataset_location(dataset),), what="--out")
    if out_dir.exists() and not out_dir.is_dir():
        raise ZendarError(f"--out {out_dir}: exists and is not a directory")
    if not out_dir.is_dir():
        return
    foreign = other_entries(out_dir, _own_output)
    if foreign:
        raise ZendarError(f"--out {out_dir} holds files that zendar-bench autolabels did not write ({foreign}); choose "
                          "a new or empty directory, or one it wrote (nothing was changed)")


def _own_output(entry: Path) -> bool:
    """Whether an entry of ``--out`` may be one :func:`write_auto_labels` wrote."""
    if entry.name == STORE_DIR:
        return True
    if entry.name == QUALITY_FILE:
        return _is_quality_document(entry)
    return owner_pid(entry) is not None


def _is_quality_document(path: Path) -> bool:
    """Whether ``path`` holds the document :func:`write_auto_labels` writes: exactly its two keys,
    ``quality`` and the text ``table`` (it carries no format marker, so its shape is the proof)."""
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return False
    return (isinstance(document, dict) and set(document) == {"quality", "table"}
            and isinstance(document["quality"], dict) and isinstance(document["table"], str))


def _remove_orphans(cluster: DaskCluster, directory: Path) -> None:
    with contextlib.suppress(OSError):
        cluster.remove_orphaned_temporaries(directory)


__all__ = ["AutoLabelTask", "LabelledScene", "label_scene", "labelled_radars", "refuse_foreign_out",
           "write_auto_labels"]
