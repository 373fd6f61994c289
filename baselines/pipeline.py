"""The steps of ``zendar-bench`` (:mod:`zendar_baselines.bench`), each writing into its step directory.

Data flow: the training scenes' cubes become normalised log-power maps (memory-mapped ``.npy`` files,
so the paper config never holds a split in memory); automatic masks of every training scene and
manual-label masks of the labelled part only are the targets; a trained model's per-cell probability
for the test scenes goes through the same chain as the CFAR baseline (DOA, SAR test, clusters).
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.detection import (
    ChainParams, FramePoints, RadarCells, frame_cube_points, frame_detections, mask_cells, to_frame,
)
from zendar_dataset.errors import ZendarError
from zendar_dataset.format import frame_id
from zendar_dataset.format.reader import SceneReader, open_dataset
from zendar_dataset.geometry.frames import EgoPoses, sar_pixel_to_ecef
from zendar_dataset.radar import FmcwParams, range_axis_m
from zendar_dataset.sar.frames import SarFrames
from zendar_dataset.temporary_files import remove_temporary, temporary_sibling

from zendar_baselines.classical import cfar_baseline
from zendar_baselines.code_version import code_version
from zendar_baselines.configs import BenchConfig
from zendar_baselines.labels.quality import combine_quality, format_quality, mask_quality
from zendar_baselines.labels.masks import MaskParams, scene_masks
from zendar_baselines.run_directory import read_json
from zendar_baselines.labels.mask_store import MaskStore
from zendar_baselines.labels.splits import SemiSupervisedSplit, make_split, read_split, write_split

SPLIT_FILE = "split.json"
STORE_DIR = "store"
CHECKPOINT_RECORD = "checkpoint.json"
#: Mask cells at or above this probability are the CNN's detections (the sigmoid's midpoint).
MASK_THRESHOLD = 0.5
#: Inference batch (frames); memory only, results do not depend on it.
PREDICT_BATCH = 8


def mask_parameters(params: MaskParams | None = None) -> dict[str, Any]:
    """The mask settings as JSON (recorded in the stores)."""
    return dataclasses.asdict(MaskParams() if params is None else params)


# --- split ---------------------------------------------------------------------------------------


def write_semi_supervised_split(root: Path, config: BenchConfig, step_dir: Path) -> None:
    """``split.json``: the training scenes' labelled and unlabelled parts (seeded by the config)."""
    split = make_split(root, config.labelled_fraction, seed=config.sim_seed)
    write_split(split, step_dir / SPLIT_FILE, dataset_root=root)


def read_semi_supervised_split(step_dir: Path, root: Path) -> SemiSupervisedSplit:
    """The split written by :func:`write_semi_supervised_split`, checked against the dataset."""
    return read_split(step_dir / SPLIT_FILE, dataset_root=root)


# --- masks ---------------------------------------------------------------------------------------


def _range_m(reader: SceneReader, radar: str, masks: np.ndarray) -> np.ndarray:
    n_range, n_doppler = masks.shape[1:]
    params = FmcwParams.from_calibration(reader.calibration.sensors[radar], n_samples=n_range, n_chirps=n_doppler)
    return range_axis_m(n_range, params.range_bin_m)


def write_auto_labels(root: Path, scene_ids: list[str], out_dir: Path, *, quality: bool = True) -> dict[str, Any] | None:
    """Automatic masks of ``scene_ids`` (a side store in ``out_dir / "store"``) and their quality.

    With ``quality``, every scene's masks are also measured against its manual-label masks and the
    pooled figures are written to ``out_dir / "quality.json"`` (and returned). They describe the
    labels, feed no model and choose nothing, so they may read the manual labels of any scene.

    Raises
    ------
    ZendarError
        For ``quality`` on a scene without labels, or a store of another dataset in ``out_dir``.
    """
    index = open_dataset(str(root))
    parameters = mask_parameters()
    store = MaskStore.create(out_dir / STORE_DIR, root, parameters, code_version=code_version())
    scores = []
    for scene_id in tqdm(sorted(scene_ids), desc="automatic labels", unit="scene"):
        with index.open_scene(scene_id) as reader:
            if store.has_scene(scene_id, parameters, code_version()):
                auto = store.scene(scene_id)
            else:
                sar = SarFrames(reader)
                auto = {radar: scene_masks(reader, radar, "auto", sar=sar, progress=False) for radar in reader.sensors("radar")}
                store.write_scene(scene_id, auto)
            if quality:
                for radar, (_, auto_masks) in auto.items():
                    _, label_masks = scene_masks(reader, radar, "labels", progress=False)
                    scores.append(mask_quality(auto_masks, label_masks, _range_m(reader, radar, auto_masks)))
    if not quality:
        return None
    pooled = combine_quality(scores)
    document = {"quality": pooled, "table": format_quality(pooled)}
    write_json_atomic(out_dir / "quality.json", document)
    return document


def write_label_masks(root: Path, split: SemiSupervisedSplit, step_dir: Path) -> None:
    """Manual-label masks of the labelled part of the training scenes only (a store of the same format)."""
    split.check_manual_label_use(split.labelled)
    index = open_dataset(str(root))
    parameters = {**mask_parameters(), "kind": "labels"}
    store = MaskStore.create(step_dir / STORE_DIR, root, parameters, code_version=code_version())
    for scene_id in tqdm(split.labelled, desc="manual-label masks", unit="scene"):
        if store.has_scene(scene_id, parameters, code_version()):
            continue
        with index.open_scene(scene_id) as reader:
            store.write_scene(scene_id, {radar: scene_masks(reader, radar, "labels", progress=False)
                                         for radar in reader.sensors("radar")})


# --- inputs --------------------------------------------------------------------------------------


def scene_maps(reader: SceneReader, radar: str, cache_dir: Path) -> np.ndarray:
    """Normalised log-power maps ``[N, A, R, D]`` float32 of one radar, memory-mapped from ``cache_dir``.

    Written once per scene and radar (atomically: temporary name, then rename) and reused.
    """
    from zendar_baselines.cnn.maps import log_power_maps

    path = cache_dir / f"{reader.scene_id}__{radar}.npy"
    if not path.is_file():
        cubes = reader.array(f"radar/{radar}/cube")
        n, n_range, n_doppler, n_rx = cubes.shape
        cache_dir.mkdir(parents=True, exist_ok=True)
        temp = temporary_sibling(path)
        try:
            maps = np.lib.format.open_memmap(temp, mode="w+", dtype=np.float32, shape=(n, n_rx, n_range, n_doppler))
            log_power_maps(cubes, out=maps)
            maps.flush()
            del maps
            os.replace(temp, path)
        finally:
            remove_temporary(temp)
    return np.load(path, mmap_mode="r")


# --- training ------------------------------------------------------------------------------------


def _frames(root: Path, scenes: list[str], store_dir: Path, window: int, cache_dir: Path):
    from torch.utils.data import ConcatDataset

    from zendar_baselines.cnn.mask_frames import MaskFrames

    index = open_dataset(str(root))
    store = MaskStore.open(store_dir, root)
    parts = []
    for scene_id in scenes:
        masks = store.scene(scene_id)
        with index.open_scene(scene_id) as reader:
            for radar in reader.sensors("radar"):
                timestamps, targets = masks[radar]
                if not np.array_equal(timestamps, reader.timestamps(f"radar/{radar}")):
                    raise ZendarError(f"{store_dir}: the masks of {scene_id} {radar} do not match the dataset's cube "
                                      "times; the store was made from another dataset")
                parts.append(MaskFrames(scene_maps(reader, radar, cache_dir), targets, window=window))
    return ConcatDataset(parts)


def train_row(out_dir: Path, root: Path, config: BenchConfig, split: SemiSupervisedSplit, auto_dir: Path,
              masks_dir: Path, inputs_dir: Path, model_name: str, pretrained: bool, seed: int, device: str) -> Path:
    """Train one seed of one Table 1 row; returns the final checkpoint (recorded in ``checkpoint.json``).

    Supervised-only: the labelled part's manual masks with ``config.supervised``. Pretrained:
    every training scene's automatic masks with ``config.pretrain``, then the labelled part's
    manual masks with ``config.finetune`` starting from those weights.
    """
    from zendar_baselines.cnn.models import build_model, parameter_count
    from zendar_baselines.cnn.training import seed_everything, train

    split.check_manual_label_use(split.labelled)
    labelled = _frames(root, list(split.labelled), masks_dir / STORE_DIR, config.window, inputs_dir)
    in_channels = labelled.datasets[0].in_channels

    def fresh_model():
        seed_everything(seed)
        return build_model(model_name, in_channels, config.width_scale).to(device)

    init_from = None
    if pretrained:
        everything = _frames(root, sorted((*split.labelled, *split.unlabelled)), auto_dir / STORE_DIR, config.window,
                             inputs_dir)
        model = fresh_model()
        result = train(model, everything, config.pretrain, seed=seed, out_dir=out_dir / "pretrain", device=device,
                       description=f"{model_name} pretrain seed {seed} ({parameter_count(model):,} parameters)")
        init_from = result.checkpoint_path
    model = fresh_model()
    schedule = config.finetune if pretrained else config.supervised
    phase = "fine-tune" if pretrained else "supervised"
    result = train(model, labelled, schedule, seed=seed, out_dir=out_dir / phase, device=device, init_from=init_from,
                   description=f"{model_name} {phase} seed {seed} ({parameter_count(model):,} parameters)")
    write_json_atomic(out_dir / CHECKPOINT_RECORD, {"checkpoint": str(result.checkpoint_path.relative_to(out_dir)),
                                             "epoch_losses": list(result.epoch_losses)})
    return result.checkpoint_path


def final_checkpoint(seed_dir: Path) -> Path:
    """The checkpoint a row's seed directory recorded."""
    return seed_dir / read_json(seed_dir / CHECKPOINT_RECORD)["checkpoint"]


# --- predictions ---------------------------------------------------------------------------------


def cfar_predictions(root: Path) -> dict[str, Any]:
    """Table 1 row 1 on the test split."""
    return cfar_baseline.cfar_predictions(str(root), "test")


#: Budget for what :class:`ScoringScenes` keeps between scorings: the test split's SAR magnitudes and
#: log-power maps (float32). The demo config's take ~280 MB; the paper config's would not fit, and
#: every scoring then reads them again.
TEST_SCENE_CACHE_BYTES = 1 << 30


@dataclasses.dataclass
class _ScoringScene:
    """One open test scene with what every scoring of it needs."""

    reader: SceneReader
    poses: EgoPoses
    sar: SarFrames
    maps: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)


class ScoringScenes:
    """The test split's scenes, opened once for many scorings (a context manager; closes them on exit).

    A default run scores 18 CNNs on the same scenes. With ``keep`` and within
    :data:`TEST_SCENE_CACHE_BYTES`, the SAR magnitudes (with their medians) and the log-power maps
    read by the first scoring are kept for the next; results equal reading the scenes afresh (the
    same arrays, read once; the maps are read-only).
    """

    def __init__(self, root: Path, *, keep: bool = True) -> None:
        self.root = Path(root)
        self.index = open_dataset(str(root))
        self.keep = keep
        self._scenes: dict[str, _ScoringScene] = {}
        self._stack = contextlib.ExitStack()

    def __enter__(self) -> ScoringScenes:
        return self

    def __exit__(self, *exc: Any) -> None:
        self._scenes.clear()
        self._stack.close()

    def scene_ids(self) -> list[str]:
        return self.index.scene_ids("test")

    def _fits(self) -> bool:
        total = 0
        for scene_id in self.scene_ids():
            with self.index.open_scene(scene_id) as reader:
                arrays = [f"sar/{s}/image" for s in reader.sensors("sar")]
                arrays += [f"radar/{r}/cube" for r in reader.sensors("radar")]
                total += sum(4 * int(np.prod(reader.array(a).shape)) for a in arrays)
        return total <= TEST_SCENE_CACHE_BYTES

    @contextlib.contextmanager
    def opened(self, scene_id: str) -> Iterator[_ScoringScene]:
        """The open scene: kept for later scorings when ``keep`` and the split fits the budget,
        else opened for this ``with`` block only."""
        if scene_id in self._scenes:
            yield self._scenes[scene_id]
            return
        if self.keep and not self._scenes and not self._fits():
            self.keep = False
        if self.keep:
            reader = self._stack.enter_context(self.index.open_scene(scene_id))
            self._scenes[scene_id] = _ScoringScene(reader, reader.ego_poses(), SarFrames(reader, keep_frames=None))
            yield self._scenes[scene_id]
            return
        with self.index.open_scene(scene_id) as reader:
            yield _ScoringScene(reader, reader.ego_poses(), SarFrames(reader))

    def maps(self, scene: _ScoringScene, radar: str) -> np.ndarray:
        """Log-power maps ``[N, A, R, D]`` of one radar of ``scene`` (kept with the scene)."""
        from zendar_baselines.cnn.maps import log_power_maps

        if radar not in scene.maps:
            maps = log_power_maps(scene.reader.array(f"radar/{radar}/cube"))
            maps.flags.writeable = False
            if not self.keep:
                return maps
            scene.maps[radar] = maps
        return scene.maps[radar]


def cnn_predictions(root: Path, config: BenchConfig, checkpoint: Path, device: str,
                    params: ChainParams | None = None, scenes: ScoringScenes | None = None) -> dict[str, Any]:
    """A trained model's detections on every test frame, through the CFAR baseline's chain.

    Per radar cube with a full window of K maps, the cells the model calls moving (probability ≥
    :data:`MASK_THRESHOLD`, score = probability) are placed by DOA, put to the SAR test and
    clustered with the other radar's points of the frame. ``scenes``: the test scenes shared with
    other scorings (:class:`ScoringScenes`); by default they are opened for this call only.
    """
    from zendar_baselines.cnn.checkpoints import load_checkpoint, load_model_state
    from zendar_baselines.cnn.models import build_model

    stored = load_checkpoint(checkpoint)  # SHA-256 against the manifest, once
    architecture = stored["architecture"]
    model = build_model(architecture["name"], architecture["in_channels"], architecture["width_scale"])
    load_model_state(model, stored, checkpoint)
    model.to(device)
    params = ChainParams() if params is None else params
    window = config.window
    if scenes is not None and scenes.root.resolve() != Path(root).resolve():
        raise ValueError(f"cnn_predictions: scenes of {scenes.root} given to score {root}")
    with contextlib.ExitStack() as stack:
        if scenes is None:
            scenes = stack.enter_context(ScoringScenes(root, keep=False))
        results = _predict_test_split(model, scenes, window, params, device, architecture["name"])
    meta = {"method": f"{architecture['name']} mask + SAR test + DBSCAN", "checkpoint": checkpoint.name,
            "architecture": architecture, "parameters": params.to_json()}
    return {"meta": meta, "results": results}


def _predict_test_split(model, scenes: ScoringScenes, window: int, params: ChainParams, device: str,
                        name: str) -> dict[str, list[dict[str, float]]]:
    """Per test frame id, the detections of ``model``'s masks through the chain (see :func:`cnn_predictions`)."""
    from zendar_baselines.cnn.maps import stack_window
    from zendar_baselines.cnn.training import predict_masks

    results: dict[str, list[dict[str, float]]] = {}
    with tqdm(desc=f"{name} test", unit="frame") as bar:
        for scene_id in scenes.scene_ids():
            with scenes.opened(scene_id) as scene:
                probability = {}
                for radar in scene.reader.sensors("radar"):
                    maps = scenes.maps(scene, radar)
                    probability[radar] = predict_masks(model, stack_window(maps, window), PREDICT_BATCH, device)

                def cells_of(radar: str, k: int, cube: np.ndarray) -> RadarCells:
                    if k < window - 1:  # no full window yet: the model has no input for this cube
                        return mask_cells(np.zeros(cube.shape[:2]))
                    return mask_cells(probability[radar][k - window + 1], MASK_THRESHOLD)

                for frame_ns, found in frame_cube_points(scene.reader, cells_of, params, poses=scene.poses,
                                                         sar=scene.sar):
                    points = FramePoints.concatenate([to_frame(cube, scene.poses, frame_ns) for cube in found])
                    results[frame_id(scene_id, frame_ns)] = frame_detections(points, params)
                    bar.update(1)
    return results


# --- bird's-eye figure ---------------------------------------------------------------------------

#: Pixels per side of the SAR image drawn in the bird's-eye figure (subsampled; a figure needs no more).
BEV_PIXELS = 300


def write_bev_figure(path: Path, root: Path, predictions: dict[str, Path]) -> Path:
    """The test frame with the most labelled cars: SAR images, ground truth, every method's detections."""
    from zendar_baselines.figures import bev_figure, write_bev

    index = open_dataset(str(root))
    best: tuple[int, str, int] | None = None
    for scene_id in index.scene_ids("test"):
        labels = index.open_scene(scene_id).labels()
        stamps, counts = np.unique(labels["timestamp_ns"], return_counts=True)
        if stamps.size and (best is None or counts.max() > best[0]):
            best = (int(counts.max()), scene_id, int(stamps[np.argmax(counts)]))
    if best is None:
        raise ZendarError(f"{root}: the test split has no labelled car to draw")
    _, scene_id, frame_ns = best
    with index.open_scene(scene_id) as reader:
        poses = reader.ego_poses()
        sar = SarFrames(reader)
        layers = []
        for sensor in sar.sensors:
            frame = sar.frame_index(sensor, frame_ns)
            if frame is None:
                continue
            image_db, _ = sar.image_db(sensor, frame)
            step = max(1, max(image_db.shape) // BEV_PIXELS)
            i, j = np.meshgrid(np.arange(0, image_db.shape[0], step), np.arange(0, image_db.shape[1], step), indexing="ij")
            points_ecef = sar_pixel_to_ecef(i, j, sar.origin[sensor][frame], sar.di[sensor][frame], sar.dj[sensor][frame])
            xy_ego = poses.ecef_to_ego(points_ecef.reshape(-1, 3), frame_ns)[:, :2].reshape(*i.shape, 2)
            layers.append((image_db[::step, ::step], xy_ego))
        labels = reader.labels()
    rows = labels["timestamp_ns"] == frame_ns
    truth = [{name: float(labels[name][k]) for name in ("x", "y", "length", "width", "yaw")} for k in np.flatnonzero(rows)]
    frame = frame_id(scene_id, frame_ns)
    detections = {label: read_json(file)["results"].get(frame, []) for label, file in predictions.items()}
    figure = bev_figure(layers, truth, detections, f"{frame}: SAR, ground truth (boxes) and detections")
    return write_bev(figure, path)
