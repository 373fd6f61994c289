"""``zendar-bench``: Table 1 of the paper, end to end, resumable.

The steps, each cached in the run directory under a key of its inputs (:mod:`run_directory`):

1. the dataset: ``--data`` or one simulated into the cache (``$XDG_CACHE_HOME/zendar-dataset/bench``);
   on a dataset without manual labels (an imported release) only the steps that need none run
   (:mod:`unlabelled`);
2. the semi-supervised split of the training scenes (``split.json``, checksummed);
3. automatic labels of every training scene (a side store beside, never inside, the dataset) and
   their precision and recall against the manual labels, per band;
4. the manual-label masks of the labelled part only, and of the validation scenes (they choose
   every training phase's checkpoint);
5. the detection chain's constants fitted on CFAR peaks of the labelled part, checked on the
   validation split (``chain_fit/cfar``, :mod:`chain_step`), and the CFAR baseline with them on the
   test split;
6. per architecture and seed: supervised-only training, pretraining on automatic labels then
   fine-tuning; the chain's constants fitted on the model's own peaks as for CFAR; each scored on
   the test split;
7. ``results.json``, ``table.md``, ``table.csv``, precision-recall plots, a bird's-eye figure and the
   training curves (``curves.png``).
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tqdm import tqdm

from zendar_dataset.atomic_files import write_json_atomic, write_text_atomic
from zendar_dataset.cluster import connected
from zendar_dataset.errors import ZendarError
from zendar_dataset.eval.report import read_metrics
from zendar_dataset.format.reader import DatasetIndex, open_dataset
from zendar_dataset.output_location import refuse_output_inside
from zendar_dataset.worker_pool import run_in_workers, usable_cpus

from zendar_baselines.bench import ranks
from zendar_baselines.bench.configs import BenchConfig
from zendar_baselines.bench.context import RowSeed, RunContext, TrainingLabels, close_kept_scenes
from zendar_baselines.bench.results_table import METHOD_NAMES, Row, csv_table, markdown_table
from zendar_baselines.bench.run_directory import STEP_RECORD, RunDirectory, read_json

if TYPE_CHECKING:
    from zendar_baselines.bench.ablations import Ablation
    from zendar_baselines.bench.scoring import ScoringScenes
    from zendar_baselines.labels.splits import SemiSupervisedSplit


@dataclass(frozen=True)
class BenchOptions:
    """What the command line asked for.

    Attributes
    ----------
    config : BenchConfig
    data : Path or None
        ``--data``: the dataset (simulated there when absent); None for the cache.
    out : Path
        ``--out``.
    seeds : int
        Training seeds per CNN row.
    device : str
        ``cpu`` or ``cuda``.
    jobs : int or None
        ``--jobs``: worker processes training CNN seeds at once (:func:`seed_jobs`); None for one per
        usable CPU.
    ablations : bool
        ``--ablations``: also the rows of :mod:`zendar_baselines.bench.ablations`.
    scheduler : str or None
        ``--scheduler``: the Dask scheduler the dataset's scenes are simulated, automatically labelled and
        predicted by the CFAR row on (docs/cluster.md);
        None for worker processes here.
    """

    config: BenchConfig
    data: Path | None
    out: Path
    seeds: int
    device: str
    jobs: int | None = None
    ablations: bool = False
    scheduler: str | None = None


def cache_root() -> Path:
    """``$XDG_CACHE_HOME/zendar-dataset/bench`` (``~/.cache/...`` when the variable is unset)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "zendar-dataset" / "bench"


def default_data_dir(config: BenchConfig) -> Path:
    """Where the simulated dataset of a configuration is cached."""
    return cache_root() / f"{config.sim_profile}-{config.n_scenes}scenes-seed{config.sim_seed}"


def say(text: str) -> None:
    """A step header on stderr, beside the progress bars."""
    print(text, file=sys.stderr, flush=True)


def data_root(options: BenchOptions) -> Path:
    """The dataset's root: ``--data``, or the cache directory of the configuration's simulated one."""
    return options.data if options.data is not None else default_data_dir(options.config)


def ensure_dataset(options: BenchOptions) -> tuple[Path, DatasetIndex, bool]:
    """The dataset to run on, it opened, and whether it has manual labels: simulated (resumably) when
    absent; checked to have labels where needed, unless no scene has any (:mod:`unlabelled`)."""
    from zendar_dataset.sim.generate import synthesize_dataset

    from zendar_baselines.bench.unlabelled import has_no_labels

    config = options.config
    root = data_root(options)
    if not (root / "dataset.json").is_file():
        # The simulator resumes its own interrupted run there and refuses a directory of other files.
        say(f"[data] simulating the {config.sim_profile} dataset ({config.n_scenes} scenes) into {root}")
        synthesize_dataset(root, profile=config.sim_profile, n_scenes=config.n_scenes, seed=config.sim_seed,
                           progress=True, jobs=1 if options.scheduler else synthesis_jobs(config.n_scenes),
                           scheduler=options.scheduler)
    index = open_dataset(str(root))
    if has_no_labels(index):
        return root, index, False
    problems = []
    for split in ("train", "test"):
        if not index.scene_ids(split):
            problems.append(f"split {split!r} has no scenes")
    for scene_id in index.scene_ids("train") + index.scene_ids("test"):
        if index.open_scene(scene_id).labels() is None:
            problems.append(f"scene {scene_id} has no labels (the bench trains on the train split's and scores the test split's; "
                            "on a dataset where no scene has any, only the steps that need none run)")
    if problems:
        raise ZendarError(f"{root}: cannot run the benchmark on this dataset:\n  " + "\n  ".join(problems))
    return root, index, True


def synthesis_jobs(n_scenes: int) -> int:
    """Worker processes for simulating: the usable CPUs, one per scene at most."""
    return max(1, min(usable_cpus(), n_scenes))


def seed_jobs(requested: int | None, n_seeds: int, device: str) -> int:
    """Worker processes for the CNN seeds: ``requested`` (default: the usable CPUs), one per seed at
    most, and one on a GPU (the seeds would share it) or under torchrun (the ranks train each seed together)."""
    if device != "cpu" or ranks.current().world_size > 1:
        return 1
    return max(1, min(usable_cpus() if requested is None else requested, n_seeds))


def run_bench(options: BenchOptions) -> dict[str, Any]:
    """Run every step (reusing finished ones) and write the outputs; returns ``results.json``'s content.

    Under torchrun, rank 0 does so and the other ranks train each CNN seed with it, write nothing and
    return an empty dict (:mod:`zendar_baselines.bench.ranks`).

    Raises
    ------
    ZendarError
        Before anything is written: ``options.out`` is inside the dataset (README: no command writes
        into a dataset it reads), or the batch sizes do not divide over torchrun's ranks.
    """
    # Before anything is simulated or written, on every rank alike: links are resolved, so an --out
    # reaching into the dataset through a symlink is refused too.
    refuse_output_inside(options.out, datasets=(data_root(options),), what="--out")
    world_size = ranks.current().world_size
    uneven = {phase: getattr(options.config, phase).batch_size for phase in ("pretrain", "finetune", "supervised")
              if getattr(options.config, phase).batch_size % world_size}
    if uneven:
        raise ZendarError(f"config {options.config.name}: the batch sizes {uneven} do not divide over torchrun's "
                          f"{world_size} ranks; run on a number of ranks that divides each of them")
    with ranks.process_group(options.device) as process:
        if not process.is_main:
            ranks.follow(_train_seed_here)
            return {}
        try:
            results = _run_bench(options)
        finally:
            close_kept_scenes()
        if process.world_size > 1:
            ranks.hand_out(None)  # the other ranks' run is over
        return results


def _train_seed_here(step: SeedStep) -> None:
    """A rank other than 0: its part of ``step``'s seed (:func:`_train_and_score`; the files are rank 0's)."""
    context = replace(step.context, progress=False)
    _train_and_score(context, step.labels, step.row, Path(context.run_path) / step.name, context.scoring_scenes(),
                     ranks.SceneShard.here())


def _run_bench(options: BenchOptions) -> dict[str, Any]:
    from zendar_baselines.bench import chain_step, scoring, steps
    from zendar_baselines.bench.autolabels import write_auto_labels

    started = time.monotonic()
    config = options.config
    RunDirectory.check_owner(options.out, {"config": config.name})
    root, dataset, labelled = ensure_dataset(options)
    context = RunContext.open(root, config, options.out, options.device, dataset)
    if not labelled:
        if ranks.current().world_size > 1:
            raise ZendarError(f"{root}: has no manual labels; zendar-bench runs the steps that need none in one "
                              "process (run it without torchrun)")
        from zendar_baselines.bench.unlabelled import run_unlabelled_bench

        return run_unlabelled_bench(context, options.seeds, options.scheduler)
    run = RunDirectory(options.out, {"config": config.name, "dataset": context.fingerprint})
    base_inputs = context.step_inputs()

    split_dir, split_key, _ = run.step("split", base_inputs, lambda d: steps.write_semi_supervised_split(context, d))
    split = steps.read_semi_supervised_split(context, split_dir)
    n_segments = sum(len(segments) for segments in split.labelled_segments.values())
    say(f"[split] {n_segments} labelled time segments in {len(split.labelled)} training scenes "
        f"({len(split.unlabelled)} training scenes without one)")

    def auto_labels(step_dir: Path) -> None:
        with connected(options.scheduler) as cluster:
            write_auto_labels(dataset, [*split.labelled, *split.unlabelled], step_dir, cluster=cluster)

    auto_dir, auto_key, _ = run.step("autolabels", {**base_inputs, "split": split_key}, auto_labels)
    quality = read_json(auto_dir / "quality.json")
    say("[autolabels] quality against the manual labels of the training scenes:\n" + quality["table"])

    masks_dir, masks_key, _ = run.step("label_masks", {**base_inputs, "split": split_key},
                                       lambda d: steps.write_label_masks(context, split, d))
    validation_dir, validation_key, _ = run.step("validation_masks", base_inputs,
                                                 lambda d: steps.write_validation_masks(context, d))
    labels = TrainingLabels(split, auto_dir, masks_dir, validation_dir)

    cfar_chain, cfar_fit, chain_key = chain_step.cfar_chain_step(run, context, split, split_key)

    def cfar_row(step_dir: Path) -> None:
        with connected(options.scheduler) as cluster:
            predictions = scoring.cfar_predictions(dataset, cfar_chain, cfar_fit, cluster=cluster)
        scoring.score_into(step_dir, predictions, root)

    rows: list[Row] = []
    cfar_dir, _, _ = run.step("rows/cfar", {**base_inputs, "chain_fit": chain_key}, cfar_row)
    rows.append(Row("cfar", METHOD_NAMES["cfar"], False, False, [read_metrics(cfar_dir / "metrics.json")]))

    seed_steps = [
        SeedStep(context, run.identity, labels, RowSeed(model_name, pretrained, seed),
                 {**base_inputs, "split": split_key, "autolabels": auto_key, "label_masks": masks_key,
                  "validation_masks": validation_key, "model": model_name, "pretrained": pretrained, "seed": seed})
        for model_name in config.models for pretrained in (False, True) for seed in range(options.seeds)
    ]
    run_seed_steps(run, seed_steps, seed_jobs(options.jobs, len(seed_steps), options.device))
    for model_name in config.models:
        for pretrained in (False, True):
            key = RowSeed(model_name, pretrained, 0).row_key
            row = Row(key, METHOD_NAMES[model_name], pretrained, True)
            row.seed_metrics = [read_metrics(run.path / step.name / "metrics.json") for step in seed_steps if step.row.row_key == key]
            _copy_first_seed(run.path / "rows" / key)
            rows.append(row)

    ablations = None
    if options.ablations:
        from zendar_baselines.bench.ablations import run_ablations

        ablations = run_ablations(run, context, labels, {"split": split_key, "autolabels": auto_key, "label_masks": masks_key,
                                                            "validation_masks": validation_key}, options.seeds,
                                  options.jobs)
    return _write_outputs(context, options.seeds, rows, quality, time.monotonic() - started, split, ablations)


@dataclass(frozen=True)
class SeedStep:
    """One CNN row seed's step: train, fit the chain on the model's peaks, score (picklable: it is
    sent to a worker process)."""

    context: RunContext
    identity: dict[str, Any]
    labels: TrainingLabels
    row: RowSeed
    inputs: dict[str, Any]
    directory: str = "rows"

    @property
    def name(self) -> str:
        """The step: ``<directory>/<row key>/seed-<k>``."""
        return f"{self.directory}/{self.row.row_key}/seed-{self.row.seed}"


def run_seed_steps(run: RunDirectory, seed_steps: list[SeedStep], jobs: int) -> None:
    """Every seed step not done yet: in this process (``jobs`` 1), on ``jobs`` worker processes of one
    thread each, or under torchrun with every rank (:mod:`zendar_baselines.bench.ranks`; rank 0 hands
    the steps out). A seed's results do not depend on where it ran (under torchrun: within DDP's
    tolerance, docs/cluster.md): training uses
    :data:`zendar_baselines.cnn.training.TRAINING_THREADS` threads either way, and each step writes
    only its own directory."""
    todo = []
    for step in seed_steps:
        if run.is_done(step.name, step.inputs):
            run.step(step.name, step.inputs, _never)  # says it is reused
        else:
            todo.append(step)
    distributed = ranks.current().world_size > 1
    if distributed:
        ranks.hand_out(todo)  # the other ranks train each of these seeds with this one
    if jobs <= 1 or len(todo) <= 1 or distributed:
        shard = ranks.SceneShard.here() if distributed else None
        test_scenes = seed_steps[0].context.scoring_scenes()  # closed with the run (close_kept_scenes)
        for step in todo:
            run.step(step.name, step.inputs,
                     lambda d, s=step: _train_and_score(s.context, s.labels, s.row, d, test_scenes, shard))
            if distributed:
                ranks.barrier()
        return
    # Longest first, so that the seeds left running alone at the end are short: pretrained seeds train
    # twice, and the later architectures of the config are the slower ones (a DenseNet-67 seed took
    # up to 2.4 times an FPN-ResNet-34 one on the demo config).
    todo = sorted(reversed(todo), key=lambda step: not step.row.pretrained)
    close_kept_scenes()  # the workers keep their own; this process passes over them no more
    say(f"[rows] {len(todo)} CNN seeds on {jobs} worker processes (one thread each)")
    with tqdm(total=len(todo), desc="CNN seeds", unit="seed") as bar:
        run_in_workers(
            _run_seed_step, todo, jobs, threads=1, on_done=lambda step, _: bar.update(),
            worker_died=lambda step: ZendarError(
                f"{step.name}: its worker process died (killed by a signal or out of memory); run zendar-bench "
                "again to resume, with --jobs 1 if memory is short"),
        )


def _never(step_dir: Path) -> None:
    raise AssertionError(f"{step_dir}: a finished step was run again")


def _run_seed_step(step: SeedStep) -> None:
    context = replace(step.context, progress=False)  # one bar in the parent counts the seeds
    run = RunDirectory(context.run_path, step.identity)
    run.step(step.name, step.inputs, lambda d: _train_and_score(context, step.labels, step.row, d, context.scoring_scenes()))


def _train_and_score(context: RunContext, labels: TrainingLabels, row: RowSeed, out_dir: Path,
                     test_scenes: ScoringScenes, shard: ranks.SceneShard | None = None) -> None:
    """Train one seed, fit its chain on its peaks, predict the test split and score it. With ``shard``
    (under torchrun, on every rank) the ranks train together and share the scenes of the fit and the
    predictions; rank 0 alone writes the files and runs the evaluator."""
    from zendar_baselines.bench import chain_step, scoring, steps

    checkpoint = steps.train_row(context, labels, row, out_dir)
    params, fit = chain_step.write_cnn_chain_fit(context, labels.split, checkpoint, row.row_key, out_dir, shard)
    predictions = scoring.cnn_predictions(context.dataset, context.config, checkpoint, context.device, params, test_scenes, fit,
                                          progress=context.progress, shard=shard)
    if ranks.is_main():
        scoring.score_into(out_dir, predictions, context.root)


def _copy_first_seed(row_dir: Path) -> None:
    """``rows/<key>/{metrics,predictions}.json``: the first seed's, beside ``seed-<k>/``."""
    for name in ("metrics.json", "predictions.json"):
        write_json_atomic(row_dir / name, read_json(row_dir / "seed-0" / name))


def _write_outputs(context: RunContext, seeds: int, rows: list[Row], quality: dict[str, Any],
                   elapsed_s: float, split: SemiSupervisedSplit, ablations: list[Ablation] | None) -> dict[str, Any]:
    from zendar_baselines.bench.car_counts import markdown_car_counts, split_car_counts
    from zendar_baselines.bench.chain_step import CFAR_STEP, chain_fit_record
    from zendar_baselines.bench.claims import claim_verdicts, markdown_claims, matched_seeds
    from zendar_baselines.bench.figures import write_bev_figure, write_loss_curves, write_pr_comparisons

    config, out = context.config, context.run_path
    title = f"Moving-car AP on the test split, config {config.name}, {seeds} seed(s) (paper Table 1 beside)"
    matched = matched_seeds(out, rows, context.root, seeds)
    verdicts = claim_verdicts(rows, matched)
    problem = next(iter(verdicts.values()))["resampling"].get("problem")
    if problem:
        say(f"[claims] {problem}")
    cars = split_car_counts(context.dataset, split)
    chain_fits = {"cfar": chain_fit_record(out / CFAR_STEP)}
    chain_fits.update({row.key: [chain_fit_record(out / "rows" / row.key / f"seed-{seed}") for seed in range(seeds)]
                       for row in rows if row.supervised})
    results = {
        "format": "zendar-bench-results",
        "format_version": 1,
        "config": config.to_json(),
        "seeds": seeds,
        "device": context.device,
        "code_version": context.code_version,
        "dataset": {"root": str(context.root), "fingerprint": context.fingerprint},
        "rows": [row.to_json() for row in rows],
        "claims": verdicts,
        "distinct_cars": cars,
        "chain_fit": chain_fits,
        "autolabel_quality": quality["quality"],
        "elapsed_s": round(elapsed_s, 1),
        "step_elapsed_s": step_times_s(out),
    }
    table = markdown_table(rows, title)
    table += "\n### The paper's claims, paired intervals (AP points)\n\n" + markdown_claims(verdicts)
    table += "\n### Distinct labelled cars\n\n" + markdown_car_counts(cars)
    if ablations is not None:
        from zendar_baselines.bench.ablations import compare_ablations, markdown_ablations

        results["ablations"] = compare_ablations(out, context.root, ablations, seeds, matched)
        ablation_table = markdown_ablations(results["ablations"], {row.key: row.ap_mean() for row in rows})
        write_text_atomic(out / "ablations.md", "### Ablations, paired intervals (AP points)\n\n" + ablation_table)
        table += "\n### Ablations, paired intervals (AP points)\n\n" + ablation_table
    write_json_atomic(out / "results.json", results)
    write_text_atomic(out / "table.md", table)
    write_text_atomic(out / "table.csv", csv_table(rows))
    write_json_atomic(out / "autolabel_quality.json", quality["quality"])
    curves = [(_label(row), row.seed_metrics[0]) for row in rows]
    write_pr_comparisons(curves, out)
    write_loss_curves(out / "curves.png", [out / "rows" / row.key for row in rows if row.supervised])
    write_bev_figure(out / "bev.png", context.dataset,
                     {_label(row): out / "rows" / row.key / "predictions.json" for row in rows})
    say(table)
    return results


def step_times_s(run_path: Path) -> dict[str, float]:
    """Step name -> seconds it took when it was computed (reused steps keep their first time; worker
    processes' steps ran side by side, so they add up to more than the wall time)."""
    times = {}
    for record in sorted(run_path.rglob(STEP_RECORD)):
        elapsed_s = read_json(record).get("elapsed_s")
        if isinstance(elapsed_s, (int, float)):
            times[record.parent.relative_to(run_path).as_posix()] = elapsed_s
    return times


def _label(row: Row) -> str:
    if not row.supervised:
        return row.method
    return f"{row.method} ({'pretrained + fine-tuned' if row.unsupervised else 'supervised only'})"
