"""``zendar-bench autolabels --scheduler``: one task per scene on a Dask cluster gives the same store and
quality as one process, a worker lost mid-scene costs nothing but time, and a scheduler that does not
answer stops the command before anything is written."""

from __future__ import annotations

import functools
import json
import os
import pathlib
import socket

import pytest

pytest.importorskip("distributed")

from zendar_dataset import cluster as cluster_module  # noqa: E402
from zendar_dataset.cli import data as data_cli  # noqa: E402
from zendar_dataset.cluster import SCHEDULER_ENV  # noqa: E402
from zendar_dataset.temporary_files import temporary_sibling  # noqa: E402

from zendar_baselines.bench import autolabels  # noqa: E402
from zendar_baselines.bench.cli import main as bench_main  # noqa: E402

# The worker processes' own task, captured before any test replaces the client's.
_LABEL_SCENE = autolabels.label_scene


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
def dataset(tmp_path_factory) -> pathlib.Path:
    root = tmp_path_factory.mktemp("autolabels") / "data"
    assert data_cli.main(["synth", str(root), "--profile", "tiny", "--scenes", "5", "--duration-s", "0.5", "--quiet"]) == 0
    return root


@pytest.fixture(scope="module")
def reference(dataset, tmp_path_factory) -> dict[str, object]:
    """The automatic labels of the training split made in this process, without a cluster."""
    out = tmp_path_factory.mktemp("reference") / "labels"
    assert bench_main(["autolabels", str(dataset), "--out", str(out)]) == 0
    return _outputs(out)


def _outputs(out: pathlib.Path) -> dict[str, object]:
    store = out / "store"
    manifest = json.loads((store / "manifest.json").read_text(encoding="utf-8"))
    return {
        "scene files": {path.name: path.read_bytes() for path in sorted(store.glob("*.npz"))},
        "manifest scenes": manifest["scenes"],
        "quality": (out / "quality.json").read_bytes(),
    }


def _temporaries(out: pathlib.Path) -> list[str]:
    return [path.name for path in (out / "store").iterdir() if ".tmp-" in path.name]


def _labelled_in(directory: str, task):
    """On a worker: label the scene, leaving a file named for the process that did it."""
    pathlib.Path(directory, f"{task.scene_id}-{os.getpid()}").touch()
    return _LABEL_SCENE(task)


def test_the_cluster_writes_the_same_store_and_quality_as_one_process(scheduler, dataset, reference, tmp_path, monkeypatch):
    monkeypatch.setenv(SCHEDULER_ENV, scheduler)  # as --scheduler, when the flag is absent
    where = tmp_path / "where"
    where.mkdir()
    monkeypatch.setattr(autolabels, "label_scene", functools.partial(_labelled_in, str(where)))
    out = tmp_path / "labels"
    assert bench_main(["autolabels", str(dataset), "--out", str(out)]) == 0
    outputs = _outputs(out)
    assert len(outputs["scene files"]) >= 2
    assert outputs == reference
    assert _temporaries(out) == []
    tasks = sorted(path.name.rsplit("-", 1) for path in where.iterdir())
    assert [scene for scene, _ in tasks] == sorted(name.removesuffix(".npz") for name in outputs["scene files"])
    assert str(os.getpid()) not in {pid for _, pid in tasks}  # every scene was labelled by a worker


def _die_mid_write_on_first_attempt(marker: str, task):
    """On a worker: the first attempt at the first scene leaves a half-written scene file under its
    temporary name and dies (``os._exit``); every other attempt labels as usual."""
    if not os.path.exists(marker):
        open(marker, "x").close()
        with open(temporary_sibling(task.store_dir / f"{task.scene_id}.npz"), "wb") as half:
            half.write(b"PK\x03\x04 half a scene")
        os._exit(1)
    return _LABEL_SCENE(task)


def test_a_worker_lost_mid_scene_is_replaced_and_the_store_is_the_same(scheduler, dataset, reference, tmp_path, monkeypatch):
    marker = tmp_path / "first-attempt"
    monkeypatch.setattr(autolabels, "label_scene", functools.partial(_die_mid_write_on_first_attempt, str(marker)))
    out = tmp_path / "labels"
    assert bench_main(["autolabels", str(dataset), "--out", str(out), "--scheduler", scheduler]) == 0
    assert marker.exists()  # the worker did die
    assert _outputs(out) == reference
    assert _temporaries(out) == []


def test_a_scheduler_that_does_not_answer_stops_autolabels_before_anything_is_written(dataset, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cluster_module, "CONNECT_TIMEOUT_S", 1.0)
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{sock.getsockname()[1]}"
    out = tmp_path / "new" / "labels"
    assert bench_main(["autolabels", str(dataset), "--out", str(out), "--scheduler", address]) == 1
    message = capsys.readouterr().err.strip()
    assert message.startswith(f"error: the Dask scheduler at {address} did not answer within 1 s")
    assert "Traceback" not in message
    assert not (tmp_path / "new").exists()
