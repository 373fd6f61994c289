"""Serial <-> side checked against the path driven, never assumed from the attitude alone: a recording
whose ``Image.attitude`` is x forward, y left, z up (sides swapped under the paper's forward-right-down)
is refused with every radar's evidence; ``--sides`` states them."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.release import fixture as fx
from tests.release.test_sdk_roundtrip import SCENE_ID, _write_release
from zendar_dataset.format import open_dataset, stores
from zendar_dataset.format.validate import validate_dataset
from zendar_dataset.release.sides import EgoPath, RadarSideEvidence, SideVotes, decide_sides

LEFT_SERIAL = next(s for s, side in fx.SERIALS.items() if side == "left")
RIGHT_SERIAL = next(s for s, side in fx.SERIALS.items() if side == "right")


def run(*args, capsys) -> tuple[int, str, str]:
    from zendar_dataset.cli.data import main

    status = main([str(a) for a in args])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


@pytest.fixture(scope="module")
def flu_release(tmp_path_factory):
    root = tmp_path_factory.mktemp("flu") / "release"
    return root, _write_release(root, "2021", flu_attitude=True)


def _serial_of(out, sensor: str) -> str:
    store = stores.open_store(out / "scenes" / f"{SCENE_ID}.zarr")
    try:
        return stores.read_attrs(stores.get_node(store.root, f"sar/{sensor}"))["serial"]
    finally:
        store.close()


def _assumptions(out) -> str:
    (scene,) = json.loads((out / "release_import.json").read_text())["scenes"]
    return " | ".join(scene["assumptions"])


def _check_sides_as_written(out, truth) -> None:
    """sar/left and detections/left hold the left radar's images and detections, as written."""
    assert _serial_of(out, "left") == LEFT_SERIAL and _serial_of(out, "right") == RIGHT_SERIAL
    reader = open_dataset(out).open_scene(SCENE_ID)
    for side in ("left", "right"):
        frames = truth["sar"][side]
        np.testing.assert_array_equal(reader.array(f"sar/{side}/origin_ecef")[:], [frame.origin_ecef for frame, _ in frames])
        positions = np.concatenate([p for _, _, p in truth["detections"][side]])
        np.testing.assert_array_equal(reader.array(f"detections/{side}/position_ecef")[:], positions)
    assert reader.calibration.radar("left").rotation_wxyz[3] > 0  # looking to ego +y


def test_flu_attitude_is_refused_with_every_radars_evidence(flu_release, tmp_path, capsys):
    src, _ = flu_release
    status, _, err = run("import-release", src, tmp_path / "out", capsys=capsys)
    assert status == 2 and "Traceback" not in err
    lines = err.strip().splitlines()
    for serial, attitude_side, path_side in ((LEFT_SERIAL, "right", "left"), (RIGHT_SERIAL, "left", "right")):
        (line,) = [line for line in lines if f"radar {serial}:" in line]
        assert f"Image.attitude (as forward-right-down -> ECEF) puts its images {attitude_side} in 10 of 10 frames" in line
        assert f"the path driven puts its images {path_side} in 10 of 10 frames" in line
        assert f"its detections {path_side} in 10 of 10 frames" in line
    assert any(f"--sides {LEFT_SERIAL}=left,{RIGHT_SERIAL}=right" in line and "not guessed" in line for line in lines)
    assert not (tmp_path / "out" / "scenes" / f"{SCENE_ID}.zarr").exists()


def test_forward_right_down_attitude_keeps_its_sides_checked(tmp_path, capsys):
    truth = _write_release(tmp_path / "release", "2021")
    status, _, err = run("import-release", tmp_path / "release", tmp_path / "out", capsys=capsys)
    assert status == 0, err
    _check_sides_as_written(tmp_path / "out", truth)
    assert f"serial {LEFT_SERIAL} -> 'left': Image.attitude and the path driven agree" in _assumptions(tmp_path / "out")


def test_stated_sides_import_the_flu_recording(flu_release, tmp_path, capsys):
    src, truth = flu_release
    out = tmp_path / "out"
    status, _, err = run("import-release", src, out, "--sides", f"{RIGHT_SERIAL}=right,{LEFT_SERIAL}=left", capsys=capsys)
    assert status == 0, err
    assert validate_dataset(out) == []
    _check_sides_as_written(out, truth)
    assert f"serial {LEFT_SERIAL} -> 'left': stated with --sides" in _assumptions(out)
    # left_rd.pbs goes with the left radar's images.
    assert "radar/left" in open_dataset(out).open_scene(SCENE_ID).streams


@pytest.mark.parametrize(
    "sides, message",
    [
        ("1739000J1Q=up", "--sides: expected SERIAL=left or SERIAL=right, got '1739000J1Q=up'"),
        ("1739000J1Q=left,1739000J2R=left", "--sides: one side is given to more than one serial"),
        ("NOPE=left", "--sides: NOPE is not a radar serial of the scenes to import (their serials: 1739000J1Q, 1739000J2R)"),
    ],
)
def test_bad_sides_exit_2_with_one_line(flu_release, tmp_path, capsys, sides, message):
    from zendar_dataset.cli.data import main

    src, _ = flu_release
    try:
        status = main(["import-release", str(src), str(tmp_path / "out"), "--sides", sides])
    except SystemExit as exc:  # argparse refuses what does not parse
        status = exc.code
    err = capsys.readouterr().err
    assert status == 2 and message in err and "Traceback" not in err
    assert not (tmp_path / "out" / "scenes" / f"{SCENE_ID}.zarr").exists()


def test_votes_need_a_clear_majority_and_the_path_needs_motion():
    votes = SideVotes()
    for lateral in (3.0, 2.0, -1.0):
        votes.add(lateral)
    assert votes.side is None and "left in 2, right in 1 of 3 frames" in votes.describe()
    votes.add(4.0)
    assert votes.side == "left"
    # A vehicle standing still has no direction of travel: nothing is left or right of its path.
    still = EgoPath(np.array([0.0, 1.0, 2.0]), np.tile(fx.ORIGIN_ECEF, (3, 1)))
    assert still.lateral_left_m(1.0, fx.ORIGIN_ECEF + 5.0) is None
    moving = EgoPath(np.array([0.0, 1.0]), fx.enu_to_ecef(np.array([[0.0, 0.0, 0.0], [8.0, 0.0, 0.0]])))  # east
    assert moving.lateral_left_m(0.5, fx.enu_to_ecef(np.array([4.0, 10.0, 0.0]))) == pytest.approx(10.0, abs=0.01)  # north


def _evidence(serial: str, attitude: float | None, path: float | None) -> RadarSideEvidence:
    """Ten frames of each reading given (lateral metres to the left), none of the others."""
    item = RadarSideEvidence(serial)
    for votes, lateral in ((item.attitude, attitude), (item.images, path), (item.detections, path)):
        for _ in range(10 if lateral is not None else 0):
            votes.add(lateral)
    return item


@pytest.mark.parametrize(
    "attitude, path, how",
    [
        (None, 10.0, "the path driven alone (Image.attitude says nothing)"),
        (10.0, None, "Image.attitude alone, not checked (the path driven says nothing"),
    ],
)
def test_one_reading_decides_when_the_other_says_nothing(attitude, path, how):
    assumed: list[str] = []
    evidence = {
        LEFT_SERIAL: _evidence(LEFT_SERIAL, attitude, path),
        RIGHT_SERIAL: _evidence(RIGHT_SERIAL, attitude and -attitude, path and -path),
    }
    assert decide_sides("scene", evidence, {}, assumed) == {LEFT_SERIAL: "left", RIGHT_SERIAL: "right"}
    assert how in assumed[0]
