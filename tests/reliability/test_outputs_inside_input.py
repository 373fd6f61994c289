"""No command writes into a dataset it reads, nor over a file it reads: refused with exit status 2
before anything is written, also through a symbolic link."""

from __future__ import annotations

import json

import pytest

from tests.format.conftest import make_dataset, tree_digest
from tests.reliability.outputs_helpers import assert_one_line_failure, run_in_process


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return make_dataset(tmp_path_factory.mktemp("inside") / "ds", "zarr")


@pytest.fixture(scope="module")
def predictions(tmp_path_factory, root):
    from zendar_dataset.format.ground_truth import ground_truth_frames

    frames = ground_truth_frames(root, "train")
    path = tmp_path_factory.mktemp("pred") / "pred.json"
    path.write_text(json.dumps({"meta": {"method": "m"}, "results": {f: [] for f in frames}}))
    return path


@pytest.fixture(scope="module")
def link_into_root(tmp_path_factory, root):
    """A symbolic link elsewhere that points at the dataset's scenes folder."""
    link = tmp_path_factory.mktemp("links") / "scenes-link"
    link.symlink_to(root / "scenes", target_is_directory=True)
    return link


CASES = {
    "convert-into-scenes": lambda r, p, link: ("zendar-data", "convert", r, r / "scenes" / "x", "--to", "hdf5"),
    "convert-into-root": lambda r, p, link: ("zendar-data", "convert", r, r, "--to", "hdf5"),
    "convert-through-link": lambda r, p, link: ("zendar-data", "convert", r, link / "x", "--to", "zarr"),
    "export-gt-into-root": lambda r, p, link: ("zendar-data", "export-gt", r, "--split", "train", "-o", r / "gt.json"),
    "export-gt-over-index": lambda r, p, link: (
        "zendar-data", "export-gt", r, "--split", "train", "-o", r / "dataset.json", "--overwrite"
    ),
    "export-gt-through-link": lambda r, p, link: (
        "zendar-data", "export-gt", r, "--split", "train", "-o", link / "gt.json"
    ),
    "eval-out-is-root": lambda r, p, link: ("zendar-eval", p, "--gt", r, "--split", "train", "--out", r),
    "eval-out-in-scenes": lambda r, p, link: ("zendar-eval", p, "--gt", r, "--split", "train", "--out", link),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_output_inside_the_input_dataset_is_refused(root, predictions, link_into_root, case):
    before = tree_digest(root)
    result = run_in_process(*CASES[case](root, predictions, link_into_root))
    assert_one_line_failure(result, 2, "inside the dataset")
    assert tree_digest(root) == before


def test_eval_out_that_would_replace_the_predictions_file_is_refused(tmp_path):
    gt = tmp_path / "gt.json"
    gt.write_text(json.dumps({"frames": {"s/1": [{"x": 10.0, "y": 0.0}]}}))
    out = tmp_path / "out"
    out.mkdir()
    predictions = out / "metrics.json"  # a user's predictions that happen to carry this name
    text = json.dumps({"results": {"s/1": [{"x": 10.0, "y": 0.0, "score": 1.0}]}})
    predictions.write_text(text)
    result = run_in_process("zendar-eval", predictions, "--gt", gt, "--out", out)
    assert_one_line_failure(result, 2, "is the input file")
    assert predictions.read_text() == text


def test_library_convert_refuses_too(root):
    from zendar_dataset.errors import ZendarError
    from zendar_dataset.format.convert import convert_dataset

    with pytest.raises(ZendarError, match="inside the dataset"):
        convert_dataset(root, root / "scenes" / "copy", to="hdf5")
    assert not (root / "scenes" / "copy").exists()
