"""Scenes on a Dask cluster (``--scheduler``), simulated or automatically labelled: the same bytes as in one
process, a worker lost mid-scene costs nothing but time, Ctrl-C leaves no half-written scene, a scheduler that does not answer (or has no
worker) and a URL output are refused before anything is written, and a worker that cannot see the output
or run the package is named."""

from __future__ import annotations

import functools
import json
import os
import pathlib
import signal
import socket
import subprocess
import sys
import time

import pytest

pytest.importorskip("distributed")

from zendar_dataset import cluster as cluster_module  # noqa: E402
from zendar_dataset.cli import data as data_cli  # noqa: E402
from zendar_dataset.cluster import SCHEDULER_ENV, DaskCluster, SharedDirectory  # noqa: E402
from zendar_dataset.errors import ZendarError  # noqa: E402
from zendar_dataset.format.reader import open_dataset  # noqa: E402
from zendar_dataset.sim import generate  # noqa: E402
from zendar_dataset.temporary_files import temporary_sibling  # noqa: E402

from zendar_baselines.bench import autolabels  # noqa: E402
from zendar_baselines.bench.cli import main as bench_main  # noqa: E402
from zendar_baselines.classical import cfar_baseline  # noqa: E402

SYNTH = ["--profile", "tiny", "--scenes", "4", "--duration-s", "0.5", "--quiet"]
REPO = pathlib.Path(__file__).resolve().parents[1]
# The worker processes' own simulation, captured before any test replaces the client's.
_RUN_TASK = generate._run_task
_LABEL_SCENE = autolabels.label_scene
_PREDICT_SCENE = cfar_baseline.predict_scene


@pytest.fixture(autouse=True)
def _no_scheduler_from_the_environment(monkeypatch):
    monkeypatch.delenv(SCHEDULER_ENV, raising=False)


@pytest.fixture(scope="module")
def scheduler():
    """The address of a local cluster of 2 one-thread worker processes; a task may lose 1 worker and be retried."""
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as local:
            yield local.scheduler_address


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Every file of the 4 scenes simulated in one process, without dask (checked: never imported)."""
    out = tmp_path_factory.mktemp("reference") / "out"
    script = ("import sys\nfrom zendar_dataset.cli.data import main\n"
              f"status = main(['synth', {str(out)!r}, *{SYNTH!r}])\n"
              "print(sorted(name for name in ('dask', 'distributed') if name in sys.modules))\n"
              "sys.exit(status)\n")
    environment = {key: value for key, value in os.environ.items() if key != SCHEDULER_ENV}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=environment, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"
    return _files(out)


def _files(root: pathlib.Path) -> dict[str, bytes]:
    return {str(path.relative_to(root)): path.read_bytes() for path in sorted(root.rglob("*")) if path.is_file()}


def _temporaries(root: pathlib.Path) -> list[str]:
    return [path.name for path in (root / "scenes").iterdir() if ".tmp-" in path.name]


def _scenes_being_written(root: pathlib.Path) -> bool:
    return (root / "scenes").is_dir() and any(name.startswith(".scene-") for name in _temporaries(root))


def _unanswered_address() -> str:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return f"tcp://127.0.0.1:{sock.getsockname()[1]}"


def test_scenes_on_the_cluster_are_byte_identical_to_one_process(scheduler, reference, tmp_path, monkeypatch):
    monkeypatch.setenv(SCHEDULER_ENV, scheduler)  # as --scheduler, when the flag is absent
    out = tmp_path / "out"
    assert data_cli.main(["synth", str(out), *SYNTH]) == 0
    files = _files(out)
    assert len(files) > 100 and files.keys() == reference.keys()
    assert [name for name in files if files[name] != reference[name]] == []
    assert _temporaries(out) == []


def _exit_mid_scene_on_first_attempt(marker: str, task):
    """On a worker: the first attempt at scene-0001 dies (``os._exit``) with its store written but not
    renamed into place; every other attempt simulates as usual."""
    if task.index == 1 and not os.path.exists(marker):
        open(marker, "x").close()
        write_scene = generate.write_scene

        def write_then_die(*args, **kwargs):
            write_scene(*args, **kwargs)
            os._exit(1)

        generate.write_scene = write_then_die
    return _RUN_TASK(task)


def test_a_worker_lost_mid_scene_is_replaced_and_the_output_is_the_same(scheduler, reference, tmp_path, monkeypatch):
    marker = tmp_path / "first-attempt"
    monkeypatch.setattr(generate, "_run_task", functools.partial(_exit_mid_scene_on_first_attempt, str(marker)))
    out = tmp_path / "out"
    assert data_cli.main(["synth", str(out), *SYNTH, "--scheduler", scheduler]) == 0
    assert marker.exists()  # the worker did die
    files = _files(out)
    assert files.keys() == reference.keys()
    assert [name for name in files if files[name] != reference[name]] == []
    assert _temporaries(out) == []


def _numba_threads(task: int) -> int:
    import numba

    return numba.get_num_threads()


def test_each_task_takes_its_workers_share_of_the_host(scheduler, tmp_path):
    from zendar_dataset.worker_pool import usable_cpus

    threads = {}
    with DaskCluster.connect(scheduler) as cluster, cluster.shared_directory(tmp_path) as shared:
        cluster.client.wait_for_workers(2)
        cluster.run(_numba_threads, range(4), shared=shared, on_done=threads.__setitem__,
                    worker_died=lambda task: AssertionError("no worker dies here"))
    assert set(threads.values()) == {max(1, usable_cpus() // 2)}  # 2 one-thread workers on this host


def _always_exit(task: int) -> int:
    os._exit(1)


def test_a_task_whose_workers_keep_dying_fails_with_the_callers_error(scheduler, tmp_path):
    with DaskCluster.connect(scheduler) as cluster, cluster.shared_directory(tmp_path) as shared:
        with pytest.raises(ZendarError, match="task 7 lost its workers"):
            cluster.run(_always_exit, [7], shared=shared, on_done=lambda task, result: None,
                        worker_died=lambda task: ZendarError(f"task {task} lost its workers"))


def _root_after_the_failure(marker: str, value: float) -> float:
    """sqrt; a negative value fails at once, the others finish only after that failure is out."""
    import math

    if value < 0:
        pathlib.Path(marker).touch()
        return math.sqrt(value)
    deadline = time.monotonic() + 30  # queued behind the failing task on one worker, it would wait for ever
    while not pathlib.Path(marker).exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.3)  # the failure's result is on its way to the client before this one's
    return math.sqrt(value)


def test_the_first_failure_is_raised_and_no_task_starts_after_it(scheduler, tmp_path):
    done = {}
    with DaskCluster.connect(scheduler) as cluster, cluster.shared_directory(tmp_path) as shared:
        with pytest.raises(ValueError, match="math domain error"):
            cluster.run(functools.partial(_root_after_the_failure, str(tmp_path / "failed")),
                        [-1.0, 4.0, 9.0, 16.0, 25.0, 36.0], shared=shared, on_done=done.__setitem__,
                        worker_died=lambda task: AssertionError("no worker dies here"))
    assert set(done) <= {4.0}  # the one task running beside the failure finished; none started after it


def test_a_worker_that_does_not_see_the_directory_fails_the_task_by_name(scheduler, tmp_path):
    unseen = SharedDirectory(tmp_path, tmp_path / ".cluster-probe.tmp-elsewhere", "token")
    with DaskCluster.connect(scheduler) as cluster:
        with pytest.raises(ZendarError, match=rf"{tmp_path} is not visible to the Dask worker tcp://.*cannot read"):
            cluster.run(abs, [-1], shared=unseen, on_done=lambda task, result: None,
                        worker_died=lambda task: AssertionError("no worker dies here"))


def test_a_worker_without_the_package_is_named(tmp_path):
    from distributed import LocalCluster

    hide = tmp_path / "hide_the_package.py"
    hide.write_text("import sys\nsys.modules['zendar_dataset'] = None\n", encoding="utf-8")
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
                      preload=[str(hide)]) as local, DaskCluster.connect(local.scheduler_address) as cluster:
        with pytest.raises(ZendarError, match=r"the Dask worker tcp://\S+ \(.*zendar_dataset.*\) cannot run this "
                                              r"package's code; install the same zendar-dataset"):
            with cluster.shared_directory(tmp_path):
                pass
    assert [path.name for path in tmp_path.iterdir()] == [hide.name]  # the probe is gone


def test_a_probe_of_another_filesystem_is_told_apart(tmp_path):
    probe = tmp_path / ".cluster-probe"
    probe.write_text("another run's token", encoding="utf-8")
    assert "another run's probe" in SharedDirectory(tmp_path, probe, "this run's token").problem_here()
    assert SharedDirectory(tmp_path, probe, "another run's token").problem_here() is None


@pytest.mark.parametrize("from_environment", [False, True])
def test_a_scheduler_that_does_not_answer_stops_the_command_before_anything_is_written(
        tmp_path, monkeypatch, capsys, from_environment):
    monkeypatch.setattr(cluster_module, "CONNECT_TIMEOUT_S", 1.0)
    address = _unanswered_address()
    out = tmp_path / "new" / "out"
    if from_environment:
        monkeypatch.setenv(SCHEDULER_ENV, address)
    argv = ["synth", str(out), *SYNTH] + ([] if from_environment else ["--scheduler", address])
    assert data_cli.main(argv) == 1
    message = capsys.readouterr().err.strip()
    assert message.startswith(f"error: the Dask scheduler at {address} did not answer within 1 s")
    assert "Traceback" not in message and len(message.splitlines()) == 1
    assert not (tmp_path / "new").exists()


def test_a_scheduler_without_workers_stops_the_command_before_anything_is_written(tmp_path, monkeypatch, capsys):
    from distributed import LocalCluster

    monkeypatch.setattr(cluster_module, "WORKER_WAIT_S", 1.0)
    with LocalCluster(n_workers=0, dashboard_address=":0") as local:
        assert data_cli.main(["synth", str(tmp_path / "out"), *SYNTH, "--scheduler", local.scheduler_address]) == 1
    message = capsys.readouterr().err
    assert f"error: the Dask scheduler at {local.scheduler_address} has no worker (waited 1 s)" in message
    assert list(tmp_path.iterdir()) == []


def test_the_bench_checks_its_scheduler_before_writing_anything(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cluster_module, "CONNECT_TIMEOUT_S", 1.0)
    address = _unanswered_address()
    argv = ["--quick", "--data", str(tmp_path / "data"), "--out", str(tmp_path / "run"), "--scheduler", address]
    assert bench_main(argv) == 1
    assert f"the Dask scheduler at {address} did not answer" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_the_bench_simulates_its_dataset_through_the_scheduler(tmp_path, monkeypatch):
    from zendar_baselines.bench.configs import get_config
    from zendar_baselines.bench.run import BenchOptions, ensure_dataset

    calls = []

    def record(out, **kwargs):
        calls.append(kwargs)
        raise ZendarError("recorded")

    monkeypatch.setattr(generate, "synthesize_dataset", record)
    options = BenchOptions(config=get_config("tiny"), data=tmp_path / "data", out=tmp_path / "run", seeds=1,
                           device="cpu", scheduler="tcp://scheduler:8786")
    with pytest.raises(ZendarError, match="recorded"):
        ensure_dataset(options)
    assert [(call["scheduler"], call["jobs"]) for call in calls] == [("tcp://scheduler:8786", 1)]


@pytest.mark.parametrize("command", ["synth", "bench"])
def test_a_url_output_is_refused_with_a_cluster(tmp_path, monkeypatch, capsys, command):
    monkeypatch.setenv(SCHEDULER_ENV, _unanswered_address())  # never reached: the URL is refused first
    if command == "synth":
        status = data_cli.main(["synth", "s3://bucket/out", *SYNTH])
    else:
        status = bench_main(["--quick", "--data", "gs://bucket/data", "--out", str(tmp_path / "run")])
    assert status == 2
    assert "is a URL; with a Dask scheduler the output must be a directory" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_jobs_and_a_scheduler_exclude_each_other(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv(SCHEDULER_ENV, _unanswered_address())
    assert data_cli.main(["synth", str(tmp_path / "out"), *SYNTH, "--jobs", "2"]) == 2
    assert "--jobs does not apply with a Dask scheduler" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


# --- automatic labels (zendar-bench autolabels --scheduler) ---------------------------------------


@pytest.fixture(scope="module")
def labelled_dataset(tmp_path_factory) -> pathlib.Path:
    root = tmp_path_factory.mktemp("autolabels") / "data"
    assert data_cli.main(["synth", str(root), "--profile", "tiny", "--scenes", "5", "--duration-s", "0.5", "--quiet"]) == 0
    return root


@pytest.fixture(scope="module")
def labels_reference(labelled_dataset, tmp_path_factory) -> dict[str, object]:
    """The automatic labels of the training split made in this process, without a cluster."""
    out = tmp_path_factory.mktemp("reference") / "labels"
    assert bench_main(["autolabels", str(labelled_dataset), "--out", str(out)]) == 0
    return _outputs(out)


def _outputs(out: pathlib.Path) -> dict[str, object]:
    store = out / "store"
    manifest = json.loads((store / "manifest.json").read_text(encoding="utf-8"))
    return {
        "scene files": {path.name: path.read_bytes() for path in sorted(store.glob("*.npz"))},
        "manifest scenes": manifest["scenes"],
        "quality": (out / "quality.json").read_bytes(),
    }


def _store_temporaries(out: pathlib.Path) -> list[str]:
    return [path.name for path in (out / "store").iterdir() if ".tmp-" in path.name]


def _labelled_in(directory: str, task):
    """On a worker: label the scene, leaving a file named for the process that did it."""
    pathlib.Path(directory, f"{task.scene_id}-{os.getpid()}").touch()
    return _LABEL_SCENE(task)


def test_the_cluster_writes_the_same_store_and_quality_as_one_process(scheduler, labelled_dataset, labels_reference,
                                                                     tmp_path, monkeypatch):
    monkeypatch.setenv(SCHEDULER_ENV, scheduler)  # as --scheduler, when the flag is absent
    where = tmp_path / "where"
    where.mkdir()
    monkeypatch.setattr(autolabels, "label_scene", functools.partial(_labelled_in, str(where)))
    out = tmp_path / "labels"
    assert bench_main(["autolabels", str(labelled_dataset), "--out", str(out)]) == 0
    outputs = _outputs(out)
    assert len(outputs["scene files"]) >= 2
    assert outputs == labels_reference
    assert _store_temporaries(out) == []
    tasks = sorted(path.name.rsplit("-", 1) for path in where.iterdir())
    assert [scene for scene, _ in tasks] == sorted(name.removesuffix(".npz") for name in outputs["scene files"])
    assert str(os.getpid()) not in {pid for _, pid in tasks}  # every scene was labelled by a worker


def _die_mid_write_on_first_attempt(marker: str, task):
    """On a worker: the first attempt at any scene leaves a half-written scene file under its temporary
    name and dies (``os._exit``); every other attempt labels as usual."""
    try:
        open(marker, "x").close()  # the two workers may try at once: one creates it, and that one dies
    except FileExistsError:
        return _LABEL_SCENE(task)
    with open(temporary_sibling(task.store_dir / f"{task.scene_id}.npz"), "wb") as half:
        half.write(b"PK\x03\x04 half a scene")
    os._exit(1)


def test_a_worker_lost_mid_scene_is_replaced_and_the_store_is_the_same(scheduler, labelled_dataset, labels_reference,
                                                                       tmp_path, monkeypatch):
    marker = tmp_path / "first-attempt"
    monkeypatch.setattr(autolabels, "label_scene", functools.partial(_die_mid_write_on_first_attempt, str(marker)))
    out = tmp_path / "labels"
    assert bench_main(["autolabels", str(labelled_dataset), "--out", str(out), "--scheduler", scheduler]) == 0
    assert marker.exists()  # the worker did die
    assert _outputs(out) == labels_reference
    assert _store_temporaries(out) == []


def test_a_scheduler_that_does_not_answer_stops_autolabels_before_anything_is_written(labelled_dataset, tmp_path,
                                                                                     monkeypatch, capsys):
    monkeypatch.setattr(cluster_module, "CONNECT_TIMEOUT_S", 1.0)
    address = _unanswered_address()
    out = tmp_path / "new" / "labels"
    assert bench_main(["autolabels", str(labelled_dataset), "--out", str(out), "--scheduler", address]) == 1
    message = capsys.readouterr().err.strip()
    assert message.startswith(f"error: the Dask scheduler at {address} did not answer within 1 s")
    assert "Traceback" not in message
    assert not (tmp_path / "new").exists()


def _predicted_in(directory: str, task):
    """On a worker: predict the scene, leaving a file named for the process that did it."""
    pathlib.Path(directory, f"{task.scene_id}-{os.getpid()}").touch()
    return _PREDICT_SCENE(task)


def _die_on_first_attempt(marker: str, task):
    """On a worker: the first attempt at any scene dies (``os._exit``); every other one predicts as usual."""
    try:
        open(marker, "x").close()
    except FileExistsError:
        return _PREDICT_SCENE(task)
    os._exit(1)


def test_cfar_predictions_on_the_cluster_equal_one_process_byte_for_byte(scheduler, labelled_dataset, tmp_path,
                                                                        monkeypatch):
    """One task per test scene on the workers (each scene by a worker, none here), a worker lost mid-scene
    replaced: the predictions document is the same bytes, in the split's scene order."""
    test_ids = open_dataset(str(labelled_dataset)).scene_ids("test")
    assert test_ids
    here = json.dumps(cfar_baseline.cfar_predictions(labelled_dataset, "test", progress=False))
    where = tmp_path / "where"
    where.mkdir()
    monkeypatch.setattr(cfar_baseline, "predict_scene", functools.partial(_predicted_in, str(where)))
    with DaskCluster.connect(scheduler) as cluster:
        there = cfar_baseline.cfar_predictions(labelled_dataset, "test", progress=False, cluster=cluster)
        assert json.dumps(there) == here and len(there["results"]) > 0
        tasks = sorted(path.name.rsplit("-", 1) for path in where.iterdir())
        assert [scene for scene, _ in tasks] == sorted(test_ids)
        assert str(os.getpid()) not in {pid for _, pid in tasks}

        marker = tmp_path / "first-attempt"
        monkeypatch.setattr(cfar_baseline, "predict_scene", functools.partial(_die_on_first_attempt, str(marker)))
        again = cfar_baseline.cfar_predictions(labelled_dataset, "test", progress=False, cluster=cluster)
        assert marker.exists() and json.dumps(again) == here


def test_a_host_that_cannot_read_the_dataset_is_named(tmp_path):
    task = cfar_baseline.CfarSceneTask(str(tmp_path / "elsewhere"), {}, "scene-0003", cfar_baseline.ChainParams())
    with pytest.raises(ZendarError, match=f"scene-0003: the dataset .*elsewhere cannot be read on host {socket.gethostname()}"):
        cfar_baseline.predict_scene(task)


def test_ctrl_c_stops_the_workers_and_removes_their_temporaries(scheduler, tmp_path):
    """Last: it restarts the workers of the shared cluster."""
    out = tmp_path / "out"
    environment = {**os.environ, SCHEDULER_ENV: scheduler}
    command = [sys.executable, "-m", "zendar_dataset.cli.data", "synth", str(out), "--profile", "tiny", "--scenes", "4",
               "--duration-s", "3", "--quiet"]
    process = subprocess.Popen(command, cwd=REPO, env=environment, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120  # against a hang only
        while not _scenes_being_written(out) and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _scenes_being_written(out), "no scene was being written"
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, stderr[-3000:]
    assert stderr.strip().splitlines()[-1] == "interrupted"
    assert _temporaries(out) == []
    settings = json.loads((out / "simulation.json").read_text(encoding="utf-8"))
    assert settings["scenes"] == 4 and not (out / "dataset.json").exists()
