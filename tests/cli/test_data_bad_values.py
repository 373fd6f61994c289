"""``zendar-data`` refuses out-of-range values and unusable outputs with exit 2, one message and nothing written."""

from __future__ import annotations

import numpy as np
import pytest

from tests.format.conftest import make_dataset
from tests.format.helpers import corrupt_chunk
from zendar_dataset.cli.data import main
from zendar_dataset.errors import ZendarError
from zendar_dataset.sim import generate
from zendar_dataset.sim.generate import MAX_SCENES, MAX_SEED, synthesize_dataset
from zendar_dataset.sim.profiles import get_profile
from zendar_dataset.sync import StreamTimes, build_sync_table


def _parse_error(capsys, args: list[str]) -> str:
    """The one ``error:`` line of a command refused while its arguments are parsed."""
    with pytest.raises(SystemExit) as exited:
        main(args)
    assert exited.value.code == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "a bug" not in err
    lines = [line for line in err.splitlines() if "error:" in line]
    assert len(lines) == 1, err
    return lines[0]


def _run(capsys, args: list[str]) -> tuple[int, str]:
    status = main([str(a) for a in args])
    err = capsys.readouterr().err
    assert "Traceback" not in err and "a bug" not in err
    return status, err


@pytest.mark.parametrize(
    ("option", "message"),
    [
        ("--seed=-1", "--seed must be between 0 and 4,294,967,295, got -1"),
        ("--seed=4294967296", "--seed must be between 0 and 4,294,967,295, got 4294967296"),
        ("--scenes=99999999999999999999", f"--scenes must be between 1 and {MAX_SCENES:,}, got 99999999999999999999"),
        ("--split-ratios=nan,0,1", "argument --split-ratios: expected finite shares"),
        ("--split-ratios=inf,0,1", "argument --split-ratios: expected finite shares"),
        ("--split-ratios=1e308,1e308,1e308", "argument --split-ratios: expected finite shares"),
    ],
)
def test_synth_refuses_a_value_out_of_range_before_writing(capsys, tmp_path, option, message):
    out = tmp_path / "out"
    line = _parse_error(capsys, ["synth", str(out), "--profile", "tiny", "--scenes", "1", option, "--quiet"])
    assert message in line
    assert not out.exists()


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("1e30", "error: the scene duration must be at most 3,600 s, got 1e+30 s"),
        ("3600.1", "error: the scene duration must be at most 3,600 s, got 3600.1 s"),
        ("nan", "error: scene duration must be a number of seconds >= 0.5, got nan"),
    ],
)
def test_synth_refuses_a_scene_duration_out_of_range_before_writing(capsys, tmp_path, value, message):
    out = tmp_path / "out"
    status, err = _run(capsys, ["synth", out, "--profile", "tiny", "--scenes", "1", f"--duration-s={value}", "--quiet"])
    assert status == 2 and message in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    "kwargs",
    [
        {"seed": -1},
        {"seed": MAX_SEED + 1},
        {"seed": 1.5},
        {"n_scenes": MAX_SCENES + 1},
        {"profile": get_profile("tiny").with_duration(3600.1)},
        {"split_ratios": (float("nan"), 0, 1)},
        {"split_ratios": (float("inf"), 0, 1)},
        {"split_ratios": (1e308, 1e308, 1e308)},
    ],
    ids=["seed-negative", "seed-2**32", "seed-fraction", "scenes", "duration", "ratio-nan", "ratio-inf", "ratio-sum-inf"],
)
def test_synthesize_dataset_refuses_a_value_out_of_range_before_writing(monkeypatch, tmp_path, kwargs):
    # Refused with the arguments: a value let through would start simulating (thousands of scenes, an hour each).
    monkeypatch.setattr(generate, "_synthesize_into", lambda *args: pytest.fail("started writing"))
    out = tmp_path / "out"
    arguments = {"profile": "tiny", "n_scenes": 1, "progress": False, **kwargs}
    with pytest.raises(ZendarError):
        synthesize_dataset(out, **arguments)
    assert not out.exists()


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("-1", "--tolerance-ms must be between 0 and 86,400,000, got -1"),
        ("1e308", "--tolerance-ms must be between 0 and 86,400,000, got 1e308"),
        ("nan", "--tolerance-ms must be a finite number, got nan"),
        ("inf", "--tolerance-ms must be a finite number, got inf"),
    ],
)
def test_info_refuses_a_tolerance_out_of_range(capsys, tmp_path, value, message):
    assert message in _parse_error(capsys, ["info", str(tmp_path), f"--tolerance-ms={value}"])


@pytest.mark.parametrize("tolerance_ms", [float("inf"), 1e308, {"camera": float("inf")}])
def test_a_tolerance_too_large_for_int64_ns_is_a_value_error(tolerance_ms):
    # Not an OverflowError from rounding to ns: the loader says which values it takes.
    times = np.arange(3, dtype=np.int64) * 100_000_000
    with pytest.raises(ValueError, match="non-negative, finite numbers of ms"):
        build_sync_table(StreamTimes("sar/left", times), [StreamTimes("camera/a", times)], tolerance_ms=tolerance_ms)


@pytest.mark.parametrize(
    ("backend", "array", "frame", "where"),
    [
        # Camera rows are small, so one block read spans all four chunk rows: the message still names the bad one.
        ("zarr", "camera/front/image", 2, "chunk [2, 0, 0, 0]: expected a readable chunk (rows 2:3)"),
        # HDF5's lzf decodes scrambled bytes without complaint (the checksum catches them); gzip does not.
        ("hdf5", "labels/moving_cars/x", 0, "chunk [0]: expected a readable chunk (rows 0:2)"),
    ],
)
def test_convert_names_an_undecodable_chunk_and_leaves_no_output(capsys, tmp_path, backend, array, frame, where):
    source = make_dataset(tmp_path / "src", backend)
    suffix = ".zarr" if backend == "zarr" else ".h5"
    corrupt_chunk(source / "scenes" / f"s1{suffix}", array, frame)
    target = "hdf5" if backend == "zarr" else "zarr"
    status, err = _run(capsys, ["convert", source, tmp_path / "out", "--to", target])
    assert status == 2
    assert f"error: s1: {array}: {where}, found a truncated or corrupt one" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["src"]  # no output, no temporary left


def test_fidelity_refuses_an_out_inside_the_dataset(capsys, tmp_path):
    root = make_dataset(tmp_path / "ds")
    (tmp_path / "link").symlink_to(root)
    before = sorted(p.name for p in root.iterdir())
    for out, named in ((root / "f", root), (tmp_path / "link" / "f", root), (root, tmp_path / "link")):
        status, err = _run(capsys, ["fidelity", named, "--out", out])
        assert status == 2 and "is inside the dataset" in err, err
    assert sorted(p.name for p in root.iterdir()) == before
