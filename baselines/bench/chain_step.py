"""The ``chain_fit`` step of ``zendar-bench``: the detection chain's constants fitted per detector.

The CFAR row's constants are fitted on CFAR peaks in a step of their own (``chain_fit/cfar``); each
CNN row's seed fits its own on that model's probability peaks, inside the seed's step, after
training (the model exists only there). Either way ``chain_fit.json`` in the step directory holds
the fitted values and the fit's summary (:func:`zendar_baselines.classical.chain_fit.fit_chain`), the
scoring records them in the predictions' meta, and ``zendar-bench verify`` re-scores with them.

The fit reads manual labels of the labelled part of the training split only (guarded by the split),
and is checked on the validation split; the test split is refused.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

from zendar_dataset.atomic_files import write_json_atomic
from zendar_dataset.detection import ChainParams
from zendar_dataset.errors import ZendarError

from zendar_baselines.bench import ranks
from zendar_baselines.bench.context import RunContext
from zendar_baselines.bench.run_directory import RunDirectory, read_json
from zendar_baselines.classical.chain_fit import CellsFor, cfar_cells_for, fit_chain
from zendar_baselines.labels.splits import SemiSupervisedSplit

CHAIN_FIT_FILE = "chain_fit.json"
#: The CFAR row's fit, under the run directory.
CFAR_STEP = "chain_fit/cfar"
FORMAT_NAME = "zendar-chain-fit"
FORMAT_VERSION = 1
#: The fitted fields of :class:`ChainParams` recorded in ``chain_fit.json``; the rest are the defaults.
FITTED = ("threshold_db", "cluster_eps_m", "centre_offset_m", "cluster_score")


def fitting_scenes(run: RunContext, split: SemiSupervisedSplit) -> tuple[list[str], list[str]]:
    """``(fit, check)`` scene ids: the scenes of the training split with a labelled segment (whose
    labelled segments alone the fit reads: :func:`write_chain_fit` passes the split on), and the
    validation split.
    """
    split.check_manual_label_use(split.labelled)
    return list(split.labelled), run.dataset.scene_ids("val")


def write_chain_fit(run: RunContext, split: SemiSupervisedSplit, detector: str, cells_for: CellsFor, base: ChainParams,
                    step_dir: Path, threshold_by: str = "points",
                    shard: ranks.SceneShard | None = None) -> tuple[ChainParams, dict[str, Any]]:
    """Fit the chain on ``detector``'s cells (``cells_for``) and write ``step_dir / chain_fit.json``
    (rank 0 writes it; with ``shard``, torchrun's ranks share the scenes and each returns the fit).

    Returns
    -------
    params, summary
        ``base`` with the fitted constants, and the fit's summary.

    Raises
    ------
    ZendarError
        As :func:`zendar_baselines.classical.chain_fit.fit_chain` (nothing is written then).
    """
    fit_ids, check_ids = fitting_scenes(run, split)
    params, summary = fit_chain(run.dataset, fit_ids, check_ids, cells_for, base, detector=detector, split=split,
                                progress=run.progress, threshold_by=threshold_by, shard=shard, scenes=run.kept_scenes())
    fitted = {"threshold_db": params.sar.threshold_db, "cluster_eps_m": params.cluster_eps_m,
              "centre_offset_m": params.centre_offset_m, "cluster_score": params.cluster_score,
              "ahead_only": params.ahead_only}
    if ranks.is_main():
        write_json_atomic(step_dir / CHAIN_FIT_FILE, {"format": FORMAT_NAME, "format_version": FORMAT_VERSION,
                                                      "detector": detector, "fitted": fitted,
                                                      "parameters": params.to_json(), "summary": summary})
    return params, summary


def cfar_chain_step(directory: RunDirectory, run: RunContext, split: SemiSupervisedSplit,
                    split_key: str) -> tuple[ChainParams, dict[str, Any], str]:
    """The ``chain_fit/cfar`` step: the CFAR row's fit on CA-CFAR peaks, reused while the run's
    inputs and the split (``split_key``, the split step's key) are unchanged.

    Returns
    -------
    params, summary, key
        The fitted constants, the fit's summary, and the step's key (for the CFAR row's inputs).
    """
    base = ChainParams()
    step_dir, key, _ = directory.step(CFAR_STEP, {**run.step_inputs(), "split": split_key},
                                      lambda d: write_chain_fit(run, split, "CFAR", cfar_cells_for(base), base, d))
    return (*read_chain_fit(step_dir), key)


def write_cnn_chain_fit(run: RunContext, split: SemiSupervisedSplit, checkpoint: Path, detector: str,
                        step_dir: Path, shard: ranks.SceneShard | None = None) -> tuple[ChainParams, dict[str, Any]]:
    """A CNN row seed's fit, on the peaks of the model in ``checkpoint``, its SAR threshold chosen by the
    detections (:func:`zendar_baselines.classical.chain_fit.fit_on_frames`); ``shard``: as :func:`write_chain_fit`."""
    from zendar_baselines.bench.scoring import CNN_CHAIN, load_model, model_cells_for, model_inputs
    from zendar_baselines.bench.steps import scene_maps

    model, architecture = load_model(checkpoint, run.device)
    channels = model_inputs(architecture)
    cells_for = model_cells_for(model, run.config.window, run.device,
                                lambda reader, radar: scene_maps(reader, radar, run.inputs_dir, channels))
    return write_chain_fit(run, split, detector, cells_for, CNN_CHAIN, step_dir, threshold_by="detections", shard=shard)


def read_chain_fit(step_dir: Path) -> tuple[ChainParams, dict[str, Any]]:
    """The fitted :class:`ChainParams` and the fit's summary from ``step_dir / chain_fit.json``.

    Raises
    ------
    ZendarError
        When the file is missing or not one :func:`write_chain_fit` wrote.
    """
    path = step_dir / CHAIN_FIT_FILE
    document = read_json(path)
    try:
        if document["format"] != FORMAT_NAME or document["format_version"] != FORMAT_VERSION:
            raise KeyError("format")
        fitted = {name: document["fitted"][name] for name in FITTED}
        # Not fitted: the SAR value's definition (the SNR subtraction and the radar's shadow, changed
        # only in their ablations; a file from before the shadow was fitted without it).
        subtract_rd_snr = document["parameters"]["sar"].get("subtract_rd_snr", True)
        shadow_margin_m = document["parameters"]["sar"].get("shadow_margin_m")
        search_radius_m = document["parameters"]["sar"].get("search_radius_m", 0.5)  # 0.5 m until 3 December
        ahead_only = document["fitted"].get("ahead_only", False)  # set from the labels' region since 3 December
        summary = document["summary"]
    except (KeyError, TypeError) as exc:
        raise ZendarError(f"{path}: not a {FORMAT_NAME} file of version {FORMAT_VERSION} ({exc!r} missing)") from None
    base = ChainParams()
    params = replace(base, sar=replace(base.sar, threshold_db=fitted["threshold_db"], subtract_rd_snr=subtract_rd_snr,
                                       shadow_margin_m=shadow_margin_m, search_radius_m=search_radius_m),
                     cluster_eps_m=fitted["cluster_eps_m"],
                     centre_offset_m=fitted["centre_offset_m"], cluster_score=fitted["cluster_score"], ahead_only=ahead_only)
    return params, summary


def chain_fit_record(step_dir: Path) -> dict[str, Any]:
    """A fit's entry of ``results.json``: the fitted constants and how well the SAR test separated the
    detector's points on labelled cars from the others (ROC AUC, all and per band) on the fitting
    frames and on the check's, with the chain's AP on the check's."""
    params, summary = read_chain_fit(step_dir)
    fit, check = summary["fit"], summary["check"]
    separation = fit["point_separation"]
    return {
        "threshold_db": params.sar.threshold_db, "cluster_eps_m": params.cluster_eps_m,
        "centre_offset_m": params.centre_offset_m, "cluster_score": params.cluster_score,
        "sar_test_auc": {"fit": {"all": separation["auc"], **separation["auc_per_band"]},
                         "check": {"all": check["auc"], **check["auc_per_band"]}},
        "check_source": check["source"], "check_ap": check["ap"],
    }
