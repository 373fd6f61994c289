"""``zendar-bench`` as a user runs it: the quick table end to end, resume, verify, and every refusal.

The quick run (tiny config, one seed) takes about two and a half minutes on 2 cores; it runs once per
test module and the other tests read its outputs.
"""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from zendar_dataset.sim.generate import synthesize_dataset
from zendar_dataset.worker_pool import usable_cpus

pytestmark = pytest.mark.slow

ROWS = [
    ("CFAR", False, False),
    ("FPN ResNet-34", False, True),
    ("FPN ResNet-34", True, True),
    ("zoom-out DenseNet-37", False, True),
    ("zoom-out DenseNet-37", True, True),
    ("zoom-out DenseNet-67", False, True),
    ("zoom-out DenseNet-67", True, True),
]
BANDS = ("near", "mid", "far", "all")


def bench(*args: str, env_home: Path, timeout: int = 900) -> subprocess.CompletedProcess:
    env = {**os.environ, "XDG_CACHE_HOME": str(env_home / "cache")}
    env.pop("ZENDAR_DEBUG", None)
    return subprocess.run(["zendar-bench", *args], capture_output=True, text=True, timeout=timeout, env=env,
                          cwd=env_home)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    home = tmp_path_factory.mktemp("bench")
    done = bench("--quick", "--out", str(home / "out"), env_home=home)
    return home, done


def test_quick_bench_writes_table_one(quick_run):
    home, done = quick_run
    assert done.returncode == 0, done.stderr[-3000:]
    assert "Traceback" not in done.stderr
    out = home / "out"
    # The dataset was simulated into the cache, never into the working directory.
    assert (home / "cache" / "zendar-dataset" / "bench").is_dir()
    if usable_cpus() >= 2:  # the seeds trained side by side, one thread each
        assert f"6 CNN seeds on {min(usable_cpus(), 6)} worker processes (one thread each)" in done.stderr
    results = json.loads((out / "results.json").read_text())
    assert [(r["method"], r["unsupervised"], r["supervised"]) for r in results["rows"]] == ROWS
    steps = results["step_elapsed_s"]  # the time of every step, as each step.json recorded it
    assert {"split", "autolabels", "chain_fit/cfar", "rows/cfar", "rows/densenet-67-pretrained/seed-0"} <= set(steps)
    assert all(seconds >= 0 for seconds in steps.values())
    assert steps["rows/cfar"] == json.loads((out / "rows" / "cfar" / "step.json").read_text())["elapsed_s"]
    for row in results["rows"]:
        assert set(row["ap"]) == set(BANDS)
        for band in BANDS:
            assert row["ap"][band] is None or 0.0 <= row["ap"][band] <= 1.0
        metrics = json.loads((out / row["metrics"]).read_text())
        assert metrics["split"] == "test" and metrics["ap"]["all"] == pytest.approx(row["ap"]["all"], abs=1e-4)
        assert "bootstrap" in metrics  # the evaluator's 95 % interval per row
        predictions = json.loads((out / row["predictions"]).read_text())
        assert len(predictions["results"]) == metrics["n_frames"]
    assert set(results["claims"]) == {"cnn_beats_cfar", "pretraining_helps", "ap_falls_with_range"}
    n_comparisons = {"cnn_beats_cfar": 6 * 3, "pretraining_helps": 3 * 3, "ap_falls_with_range": 7 * 2}
    for name, claim in results["claims"].items():
        assert claim["verdict"] in ("holds", "fails", "undecided")
        assert claim["resampling"]["unit"] == "scene_time_block" and claim["resampling"]["seeds_compared"] == "all"
        assert claim["resampling"]["seeds"] == {row["key"]: results["seeds"] if row["supervised"] else 1 for row in results["rows"]}
        assert len(claim["comparisons"]) == n_comparisons[name]
        for comparison in claim["comparisons"]:
            low, high = comparison["ci95"]
            assert comparison["verdict"] in ("holds", "fails", "undecided")
            assert low is None or low <= high
    assert set(results["distinct_cars"]) == {"train_labelled", "train", "val", "test"}
    # Independently: distinct (scene, track id) within 60 m in the evaluator's ground truth of the test split.
    from zendar_dataset.format.ground_truth import ground_truth_frames

    frames = ground_truth_frames(results["dataset"]["root"], "test")
    within = {(f.rpartition("/")[0], car["track_id"]) for f, cars in frames.items() for car in cars
              if (car["x"] ** 2 + car["y"] ** 2) ** 0.5 < 60.0}
    test_cars = results["distinct_cars"]["test"]
    assert test_cars["cars"]["all"] == len(within) == sum(test_cars["by_kind"]["all"].values())
    table = (out / "table.md").read_text()
    assert "| claim | pair | band | difference [95 % interval] | verdict |" in table
    assert "### Distinct labelled cars" in table
    assert "| CFAR | - | - |" in table and "| 65.0 | 43.0 | 13.3 |" in table  # ours beside the paper's
    with open(out / "table.csv", newline="") as handle:
        assert [line["method"] for line in csv.DictReader(handle)] == [method for method, _, _ in ROWS]
    for picture in ("pr_near.png", "pr_mid.png", "pr_far.png", "pr_all.png", "bev.png", "curves.png"):
        assert (out / picture).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for row in results["rows"][1:]:
        seed_dir = out / "rows" / row["key"] / "seed-0"
        record = json.loads((seed_dir / "checkpoint.json").read_text())
        assert record["validation"]["source"] == "val split"
        phases = ["pretrain", "fine-tune"] if row["unsupervised"] else ["supervised"]
        assert list(record["phases"]) == phases
        curves = json.loads((seed_dir / "curves.json").read_text())
        for phase, curve in zip(record["phases"].values(), curves["phases"]):
            assert len(curve["epochs"]) == phase["epochs_run"] == len(phase["validation_losses"])
            assert phase["best_epoch"] == 1 + min(range(phase["epochs_run"]), key=phase["validation_losses"].__getitem__)
    quality = json.loads((out / "autolabel_quality.json").read_text())
    assert set(quality["bands"]) == set(BANDS) and quality["n_frames"] > 0
    # The chain's constants, fitted per detector on the labelled part and checked on validation.
    split = json.loads((out / "split" / "split.json").read_text())
    for fit_dir in [out / "chain_fit" / "cfar", *sorted((out / "rows").glob("*/seed-*"))]:
        fit = json.loads((fit_dir / "chain_fit.json").read_text())
        assert fit["summary"]["fit"]["scenes"] == split["labelled"] and fit["summary"]["check"]["source"] == "val"
        assert fit["fitted"]["cluster_score"] == ("sum" if fit_dir.name == "cfar" else "max")
    for row in results["rows"]:
        meta = json.loads((out / row["predictions"]).read_text())["meta"]
        assert meta["chain_fit"]["threshold_db"] == meta["parameters"]["sar"]["threshold_db"]
    # results.json records every fit: the constants and the SAR test's ROC AUC per band, fit and check.
    fits = results["chain_fit"]
    assert set(fits) == {"cfar"} | {row["key"] for row in results["rows"] if row["supervised"]}
    cfar_fit = json.loads((out / "chain_fit" / "cfar" / "chain_fit.json").read_text())
    assert fits["cfar"]["threshold_db"] == cfar_fit["fitted"]["threshold_db"]
    assert fits["cfar"]["sar_test_auc"]["fit"] == {"all": cfar_fit["summary"]["fit"]["point_separation"]["auc"],
                                                   **cfar_fit["summary"]["fit"]["point_separation"]["auc_per_band"]}
    assert set(fits["cfar"]["sar_test_auc"]["check"]) == set(BANDS)


def test_the_split_never_shows_unlabelled_scenes_labels(quick_run):
    home, _ = quick_run
    out = home / "out"
    split = json.loads((out / "split" / "split.json").read_text())
    label_store = json.loads((out / "label_masks" / "store" / "manifest.json").read_text())
    assert sorted(label_store["scenes"]) == sorted(split["labelled"])
    assert not set(split["labelled"]) & set(split["unlabelled"])


def test_a_second_run_reuses_every_step_and_gives_the_same_table(quick_run):
    home, first = quick_run
    before = (home / "out" / "table.md").read_text()
    again = bench("--quick", "--out", str(home / "out"), env_home=home)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "epoch" not in again.stderr  # nothing trained again
    assert again.stderr.count("reused") >= 1 + 1 + 1 + 1 + 6
    assert (home / "out" / "table.md").read_text() == before


def test_verify_rescores_from_the_checkpoints(quick_run):
    home, _ = quick_run
    done = bench("verify", "--out", str(home / "out"), env_home=home)
    assert done.returncode == 0, done.stdout + done.stderr[-2000:]
    assert "every row reproduces" in done.stdout
    assert "ok   claims: 41 paired comparisons recomputed from the recorded predictions" in done.stdout


def test_scorings_sharing_the_test_scenes_give_the_recorded_predictions_exactly(quick_run, monkeypatch):
    """The run scores every CNN through one ScoringScenes (SAR magnitudes and maps read once): a model
    scored on kept scenes, on fresh ones, and with the cache over its budget gives the same bytes."""
    from zendar_baselines.bench import chain_step, scoring, steps
    from zendar_baselines.classical import kept_scenes
    from zendar_baselines.bench.configs import get_config

    home, _ = quick_run
    out = home / "out"
    root = Path(json.loads((out / "results.json").read_text())["dataset"]["root"])
    config = get_config("tiny")
    seed_dirs = [out / "rows" / key / "seed-0" for key in ("densenet-37-pretrained", "fpn-resnet34-supervised")]
    recorded = [json.loads((d / "predictions.json").read_text())["results"] for d in seed_dirs]

    def score(seed_dir, scenes=None):
        params, _ = chain_step.read_chain_fit(seed_dir)  # the constants the run fitted on this model's peaks
        return scoring.cnn_predictions(root, config, steps.final_checkpoint(seed_dir), "cpu", params, scenes)["results"]

    with scoring.ScoringScenes(root) as scenes:
        kept = [score(d, scenes) for d in seed_dirs] + [score(seed_dirs[0], scenes)]
        first = scenes.scene_ids()[0]
        with scenes.opened(first) as scene, scenes.opened(first) as again:
            assert again is scene and scene.maps
            assert all(not maps.flags.writeable for maps in scene.maps.values())
        with pytest.raises(ValueError, match="scenes of"):
            scoring.cnn_predictions(home, config, steps.final_checkpoint(seed_dirs[0]), "cpu", scenes=scenes)
    assert kept == [*recorded, recorded[0]]
    assert score(seed_dirs[1]) == recorded[1]
    monkeypatch.setattr(kept_scenes, "KEPT_SCENE_BYTES", 0)
    with scoring.ScoringScenes(root) as scenes:
        assert score(seed_dirs[0], scenes) == recorded[0]
        with scenes.opened(first) as scene, scenes.opened(first) as again:
            assert not scenes.keep and again is not scene


def test_a_seed_trained_in_this_process_equals_the_one_a_worker_trained(quick_run, tmp_path):
    """The quick run trains its seeds on worker processes; with one seed removed, ``--jobs 1`` trains
    it again here and every output reads the same: results do not depend on where a seed ran."""
    home, _ = quick_run
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-a", str(home / "out"), str(copy)], check=True)
    seed_dir = copy / "rows" / "densenet-37-supervised" / "seed-0"
    recorded = {name: (seed_dir / name).read_text() for name in ("predictions.json", "metrics.json", "chain_fit.json")}
    subprocess.run(["rm", "-r", str(seed_dir)], check=True)
    done = bench("--quick", "--jobs", "1", "--out", str(copy), env_home=home)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "worker processes" not in done.stderr and "densenet-37 supervised seed 0" in done.stderr
    assert {name: (seed_dir / name).read_text() for name in recorded} == recorded
    assert (copy / "table.md").read_text() == (home / "out" / "table.md").read_text()


def test_under_torchrun_every_rank_trains_each_seed_and_rank_0_alone_writes_the_run(quick_run, tmp_path):
    """``torchrun --nproc-per-node 2 -m zendar_baselines --quick`` on the quick run with two seeds removed:
    the other steps are reused, the two seeds are trained by both ranks (DistributedDataParallel over
    gloo, recorded in their checkpoints), the run is written once, and the retrained rows match the
    one-process ones within DDP's tolerance: each rank's batch-norm statistics come from its half of
    the batch, so the first epoch's loss agrees to 2 % and the AP over all bands to 0.05 (measured:
    0.03 % and 1.1 %; -0.011 and +0.014 AP). The ranks shared the scenes of each seed's chain fit and
    predictions: ``verify`` re-scores every seed from its checkpoint in one process to the same AP."""
    from zendar_baselines.cnn.checkpoints import load_checkpoint

    home, _ = quick_run
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-a", str(home / "out"), str(copy)], check=True)
    retrained = ("fpn-resnet34-supervised", "fpn-resnet34-pretrained")
    kept = sorted(path for path in (copy / "rows").rglob("*")
                  if path.is_file() and path.relative_to(copy / "rows").parts[0] not in retrained)
    kept_bytes = {path: path.read_bytes() for path in kept if path.suffix != ".pt"}
    before = {key: _seed_record(copy, key) for key in retrained}
    for key in retrained:
        subprocess.run(["rm", "-r", str(copy / "rows" / key / "seed-0")], check=True)
    env = {**os.environ, "XDG_CACHE_HOME": str(home / "cache")}
    # torchrun as a module of this interpreter: the ranks run the package installed here.
    done = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
                           "-m", "zendar_baselines", "--quick", "--out", str(copy)],
                          capture_output=True, text=True, timeout=600, env=env, cwd=home)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "[rows/cfar] reused" in done.stderr and "[rows/densenet-37-supervised/seed-0] reused" in done.stderr
    assert done.stdout.count("wrote ") == 1  # rank 0 alone says what it wrote
    assert {path: path.read_bytes() for path in kept_bytes} == kept_bytes
    for key in retrained:
        after = _seed_record(copy, key)
        checkpoint = load_checkpoint(copy / "rows" / key / "seed-0" / after["checkpoint"])
        assert checkpoint["config"]["world_size"] == 2
        assert after["first_loss"] == pytest.approx(before[key]["first_loss"], rel=0.02)
        assert after["ap_all"] == pytest.approx(before[key]["ap_all"], abs=0.05)
    assert [name for name in copy.rglob("*") if ".tmp-" in name.name] == []
    verified = bench("verify", "--out", str(copy), env_home=home)
    assert verified.returncode == 0 and "every row reproduces" in verified.stdout, verified.stdout[-2000:]


def test_ranks_that_do_not_divide_the_batch_are_refused_before_anything_is_written(tmp_path, monkeypatch, capsys):
    from zendar_baselines.bench.cli import main as bench_main

    monkeypatch.setenv("WORLD_SIZE", "3")
    monkeypatch.setenv("RANK", "0")
    assert bench_main(["--quick", "--out", str(tmp_path / "out")]) == 2
    message = capsys.readouterr().err
    assert "the batch sizes {'pretrain': 16, 'finetune': 16, 'supervised': 16} do not divide over torchrun's 3 ranks" in message
    assert list(tmp_path.iterdir()) == []


def _seed_record(run: Path, key: str) -> dict:
    seed_dir = run / "rows" / key / "seed-0"
    record = json.loads((seed_dir / "checkpoint.json").read_text())
    first_phase = next(iter(record["phases"].values()))
    return {"checkpoint": record["checkpoint"], "first_loss": first_phase["train_losses"][0],
            "ap_all": json.loads((seed_dir / "metrics.json").read_text())["ap"]["all"]}


def test_ablations_add_their_rows_with_paired_differences_and_reuse_the_table(quick_run, tmp_path):
    """``--ablations`` on a finished run: Table 1's steps are reused, the ablation rows are made (the
    CFAR row with the SAR reading alone, without the radar's shadow and with the 0.5 m window, FPN
    ResNet-34 supervised on CFAR-gated targets and with extra input channels), and each difference on
    all frames is the two rows' AP as the evaluator scored them."""
    home, _ = quick_run
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-a", str(home / "out"), str(copy)], check=True)
    done = bench("--quick", "--ablations", "--out", str(copy), env_home=home)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "[rows/cfar] reused" in done.stderr and "fpn-resnet34 supervised seed 0" in done.stderr
    results = json.loads((copy / "results.json").read_text())
    assert [a["ablation"] for a in results["ablations"]] == [
        "sar-reading-alone", "no-radar-shadow", "sar-window-0.5m", "cfar-gated-targets", "phase-difference-channels",
        "static-doppler-channel"]
    assert [a["reference"] for a in results["ablations"]] == ["cfar", "cfar", "cfar", *["fpn-resnet34-supervised"] * 3]
    row_aps = {row["key"]: row["ap"] for row in results["rows"]}
    for ablation in results["ablations"]:
        row_ap, reference_ap = ablation["row"]["ap"], row_aps[ablation["reference"]]  # seed means
        for band, comparison in ablation["minus_reference"].items():
            if row_ap[band] is not None and reference_ap[band] is not None:
                # Three values each rounded to 4 decimals: up to 1.5e-4 apart.
                assert comparison["difference"] == pytest.approx(row_ap[band] - reference_ap[band], abs=1.5e-4)
            assert comparison["reading"] in ("higher", "lower", "no difference shown")
    meta = json.loads((copy / "ablations" / "sar-reading-alone" / "row" / "predictions.json").read_text())["meta"]
    assert meta["parameters"]["sar"]["value"] == "SAR reading" and meta["parameters"]["sar"]["shadow_margin_m"] > 0
    meta = json.loads((copy / "ablations" / "no-radar-shadow" / "row" / "predictions.json").read_text())["meta"]
    assert meta["parameters"]["sar"]["shadow_margin_m"] is None
    assert meta["parameters"]["sar"]["value"] == "SAR reading minus range-Doppler SNR"
    meta = json.loads((copy / "ablations" / "sar-window-0.5m" / "row" / "predictions.json").read_text())["meta"]
    assert meta["parameters"]["sar"]["search_radius_m"] == 0.5
    assert json.loads((copy / "rows" / "cfar" / "predictions.json").read_text())["meta"]["parameters"]["sar"]["search_radius_m"] == 0.2
    store = json.loads((copy / "ablations" / "cfar-gated-targets" / "label_masks" / "store" / "manifest.json").read_text())
    assert store["parameters"]["manual_targets"] == "cfar-peaks"
    # The channel rows' models read their own inputs: 4 antennas' log power and 6 phase channels, or 1
    # residual channel, per map of the window; the reference row's the log power alone.
    window = json.loads((copy / "results.json").read_text())["config"]["window"]
    channel_rows = {a["ablation"]: a["row"] for a in results["ablations"]}
    for name, per_map in (("phase-difference-channels", 10), ("static-doppler-channel", 5)):
        meta = json.loads((copy / channel_rows[name]["predictions"]).read_text())["meta"]
        assert meta["architecture"]["in_channels"] == window * per_map
        assert set(meta["architecture"]["inputs"].values()) == {True, False}
    meta = json.loads((copy / "rows" / "fpn-resnet34-supervised" / "predictions.json").read_text())["meta"]
    assert meta["architecture"]["in_channels"] == window * 4 and "inputs" not in meta["architecture"]
    table = (copy / "ablations.md").read_text()
    assert "sar-reading-alone (vs cfar)" in table and "cfar-gated-targets (vs fpn-resnet34-supervised)" in table
    assert (copy / "ablations.md").read_text() in (copy / "table.md").read_text()


def test_verify_names_a_damaged_checkpoint(quick_run, tmp_path):
    home, _ = quick_run
    copy = tmp_path / "copy"
    subprocess.run(["cp", "-a", str(home / "out"), str(copy)], check=True)
    seed_dir = copy / "rows" / "densenet-37-supervised" / "seed-0"
    checkpoint = seed_dir / json.loads((seed_dir / "checkpoint.json").read_text())["checkpoint"]
    data = bytearray(checkpoint.read_bytes())
    data[len(data) // 2] ^= 0xFF
    checkpoint.write_bytes(bytes(data))
    done = bench("verify", "--out", str(copy), env_home=home)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert checkpoint.name in done.stderr


def test_an_out_holding_someone_elses_files_is_refused_untouched(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    done = bench("--quick", "--out", str(out), env_home=tmp_path, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "holds files that zendar-bench did not write (notes.txt)" in done.stderr
    assert [p.name for p in out.iterdir()] == ["notes.txt"] and (out / "notes.txt").read_text() == "mine"
    assert not (tmp_path / "cache").exists()  # refused before simulating anything


def test_a_run_of_another_config_is_refused(quick_run):
    home, _ = quick_run
    done = bench("--config", "demo", "--out", str(home / "out"), env_home=home, timeout=120)
    assert done.returncode == 2 and "holds a zendar-bench run of" in done.stderr


def test_a_dataset_without_test_labels_is_refused(tmp_path):
    data = tmp_path / "withheld"
    synthesize_dataset(data, profile="tiny", n_scenes=5, withhold_test_labels=True, progress=False)
    done = bench("--quick", "--data", str(data), "--out", str(tmp_path / "out"), env_home=tmp_path, timeout=300)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert "has no labels" in done.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--seeds", "0"], "expected 1 to 100 seeds"),
        (["--seeds", "three"], "expected a whole number of seeds"),
        (["--config", "huge"], "invalid choice: 'huge'"),
        (["--jobs", "0"], "--jobs must be 1 or more, got 0"),
        (["--device", "tpu"], "invalid choice: 'tpu'"),
    ],
)
def test_bad_arguments_exit_2_with_the_reason(tmp_path, args, message):
    done = bench(*args, "--out", str(tmp_path / "out"), env_home=tmp_path, timeout=60)
    assert done.returncode == 2 and message in done.stderr and "Traceback" not in done.stderr


@pytest.mark.skipif(sys.platform != "linux", reason="checks torch's CUDA probe on the CI machines")
def test_cuda_without_a_device_is_a_clear_refusal(tmp_path):
    import torch

    if torch.cuda.is_available():
        pytest.skip("a CUDA device is present")
    done = bench("--quick", "--device", "cuda", "--out", str(tmp_path / "out"), env_home=tmp_path, timeout=60)
    assert done.returncode == 2 and "no CUDA device" in done.stderr


@pytest.fixture(scope="module")
def small_dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("small") / "data"
    synthesize_dataset(root, profile="tiny", n_scenes=4, progress=False)
    return root


def test_autolabels_command_writes_a_side_store_with_its_quality(small_dataset, tmp_path):
    out = tmp_path / "labels"
    done = bench("autolabels", str(small_dataset), "--out", str(out), env_home=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    manifest = json.loads((out / "store" / "manifest.json").read_text())
    train = json.loads((small_dataset / "dataset.json").read_text())["splits"]["train"]
    assert manifest["format"] == "zendar-autolabels" and sorted(manifest["scenes"]) == sorted(train)
    assert "cell P" in done.stdout and "near" in done.stdout
    quality = json.loads((out / "quality.json").read_text())["quality"]
    assert 0.0 <= quality["bands"]["all"]["cell_precision"] <= 1.0
    again = bench("autolabels", str(small_dataset), "--out", str(out), env_home=tmp_path, timeout=300)
    assert again.returncode == 0 and json.loads((out / "store" / "manifest.json").read_text())["scenes"] == manifest["scenes"]


def test_autolabels_at_another_sar_threshold_are_recorded_and_call_more_points_moving(small_dataset, tmp_path):
    """A higher threshold calls more points dynamic (the test is "dynamic below it"): at 200 dB every point
    with a SAR reading is, so the automatic labels hold at least as many MOVING cells as at the default,
    and the store records the threshold it was made with."""
    default, high = tmp_path / "default", tmp_path / "high"
    assert bench("autolabels", str(small_dataset), "--out", str(default), env_home=tmp_path, timeout=300).returncode == 0
    done = bench("autolabels", str(small_dataset), "--out", str(high), "--threshold-db", "200", env_home=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    parameters = json.loads((high / "store" / "manifest.json").read_text())["parameters"]
    assert parameters["chain"]["sar"]["threshold_db"] == 200.0

    def moving_cells(out):
        counts = json.loads((out / "quality.json").read_text())["quality"]["bands"]["all"]["counts"]
        return counts["tp_cells"] + counts["fp_cells"]

    assert moving_cells(high) > moving_cells(default) > 0
    bad = bench("autolabels", str(small_dataset), "--out", str(tmp_path / "bad"), "--threshold-db", "nan",
                env_home=tmp_path, timeout=120)
    assert bad.returncode == 2 and "threshold_db must be a finite number of dB" in bad.stderr
    assert not (tmp_path / "bad").exists()


def test_autolabels_are_never_written_inside_the_dataset(small_dataset, tmp_path):
    before = sorted(p.relative_to(small_dataset) for p in small_dataset.rglob("*"))
    done = bench("autolabels", str(small_dataset), "--out", str(small_dataset / "labels"), env_home=tmp_path, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert sorted(p.relative_to(small_dataset) for p in small_dataset.rglob("*")) == before


def test_verify_of_a_directory_that_is_not_a_run_is_refused(tmp_path):
    (tmp_path / "out").mkdir()
    done = bench("verify", "--out", str(tmp_path / "out"), env_home=tmp_path, timeout=60)
    assert done.returncode == 2 and "not a finished zendar-bench run" in done.stderr and "Traceback" not in done.stderr


def test_ablation_differences_pool_every_seed_of_both_rows(quick_run, tmp_path):
    """Two seeds per row, laid out as a run lays them out: the ablation row's seeds under
    ``ablations/<name>/<row>/seed-<k>``, the reference's under ``rows/<row>/seed-<k>``. The ablation's
    seeds both predict as the quick run's first seed; the reference's second seed predicts nothing (AP
    0), so the difference of seed means is half the first seed's AP in every band. The leftover third
    seed folders of an earlier, larger run are not read."""
    from zendar_baselines.bench.ablations import Ablation, compare_ablations
    from zendar_baselines.bench.results_table import Row

    home, _ = quick_run
    out = home / "out"
    dataset = next((home / "cache" / "zendar-dataset" / "bench").iterdir())
    seed_dir = out / "rows" / "fpn-resnet34-supervised" / "seed-0"
    first = json.loads((seed_dir / "predictions.json").read_text())
    first_ap = json.loads((seed_dir / "metrics.json").read_text())["ap"]
    empty = {**first, "results": {frame: [] for frame in first["results"]}}
    layouts = {"ablations/x/fpn-resnet34-supervised": (first, first, empty), "rows/fpn-resnet34-supervised": (first, empty, first)}
    for folder, seeds in layouts.items():
        for k, predictions in enumerate(seeds):
            (run := tmp_path / "run" / folder / f"seed-{k}").mkdir(parents=True)
            (run / "predictions.json").write_text(json.dumps(predictions))
    row = Row("fpn-resnet34-supervised-x", "FPN ResNet-34", False, True)
    ablation = Ablation("x", "nothing", "fpn-resnet34-supervised", row, "ablations/x/fpn-resnet34-supervised/seed-0")
    [record] = compare_ablations(tmp_path / "run", dataset, [ablation], seeds=2)
    assert record["resampling"]["seeds"] == {"fpn-resnet34-supervised-x": 2, "fpn-resnet34-supervised": 2}
    assert any(first_ap[band] for band in record["minus_reference"])
    for band, comparison in record["minus_reference"].items():
        if first_ap[band] is None:
            assert comparison["difference"] is None
        else:
            assert comparison["difference"] == pytest.approx(first_ap[band] / 2, abs=1e-4)
    # The claims' matching of the reference is reused, not made again from rows/: given the ablation's
    # own seeds as the reference's matching, every difference is 0.
    from zendar_baselines.bench.claims import matched_predictions, seed_predictions

    same = matched_predictions({"r": seed_predictions(tmp_path / "run" / "ablations/x/fpn-resnet34-supervised", 2)}, dataset)
    [again] = compare_ablations(tmp_path / "run", dataset, [ablation], seeds=2, matched={"fpn-resnet34-supervised": same["r"]})
    assert all(c["difference"] in (None, 0.0) for c in again["minus_reference"].values())


def test_an_ablation_records_every_seed_outputs(quick_run):
    from zendar_dataset.eval.report import read_metrics

    from zendar_baselines.bench.ablations import Ablation
    from zendar_baselines.bench.results_table import Row

    home, _ = quick_run
    metrics = read_metrics(home / "out" / "rows" / "fpn-resnet34-supervised" / "seed-0" / "metrics.json")
    row = Row("fpn-resnet34-supervised-x", "FPN ResNet-34", False, True, [metrics, metrics, metrics])
    record = Ablation("x", "nothing", "fpn-resnet34-supervised", row, "ablations/x/seed-0").to_json()
    assert record["metrics"] == "ablations/x/seed-0/metrics.json"
    assert record["seed_outputs"] == [{"metrics": f"ablations/x/seed-{k}/metrics.json",
                                       "predictions": f"ablations/x/seed-{k}/predictions.json"} for k in range(3)]
    cfar = Ablation("y", "nothing", "cfar", Row("cfar-y", "CFAR", False, False, [metrics]), "ablations/y/row").to_json()
    assert cfar["seed_outputs"] == [{"metrics": "ablations/y/row/metrics.json", "predictions": "ablations/y/row/predictions.json"}]
