"""Settings of the detection chain and the classical detector's constants."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from zendar_dataset.detection.static_scene import SarTestParams
from zendar_dataset.errors import ZendarError

CFAR_PFA = 1e-4
CLUSTER_EPS_M = 1.5  # about half a car length: one car's scatterers chain into one cluster

# Along the line of sight, labelled centres lie this far beyond the clusters' centres: the median
# over the clusters of the demo training split (`zendar-data synth ROOT --profile demo --scenes 5`,
# `zendar-bench fit-chain ROOT --split train`) with a label within 4 m. About half a car's length:
# most cars are seen from behind or ahead, in the ego's own street.
DEFAULT_CENTRE_OFFSET_M = 2.09

# How a cluster's dynamic members' scores make its score (before the dynamic share): their sum, or
# their maximum. The sum suits CFAR's linear SNRs: heavy-tailed, so a cluster's sum is about its
# strongest peak's. A CNN's probabilities are bounded by 1, so their sum counts members and big
# diffuse clusters would rank first; its peaks take the maximum (docs/baselines.md, "Cluster score").
CLUSTER_SCORES = ("sum", "max")


@dataclass(frozen=True)
class ChainParams:
    """Settings of the detection chain.

    Attributes
    ----------
    cfar_pfa : float
        False-alarm probability of the CA-CFAR (the classical detector's).
    sar : SarTestParams
        The static-scene test.
    cluster_eps_m : float
        DBSCAN neighbourhood, metres (about half a car length: one car's scatterers chain into one
        cluster).
    centre_offset_m : float
        Each detection moves this far along the line of sight away from the radars.
    cluster_score : str
        One of :data:`CLUSTER_SCORES`: a cluster scores the sum (CFAR) or the maximum (CNN peaks)
        of its dynamic members' scores, times its dynamic share.
    ahead_only : bool
        Keep only detections whose centre is ahead of the ego's front bumper (ego x > 0). For labels
        that hold only cars there (the simulator's: a car is labelled only when its centre is ahead of
        the bumper, docs/simulator.md "Labels"), a detection of a car beside the ego has no label to
        match and is a false positive to the evaluator. False (default) keeps every detection; the
        chain fit sets it from the labels it fits on (``zendar_baselines.classical.chain_fit``).
    """

    cfar_pfa: float = CFAR_PFA
    sar: SarTestParams = field(default_factory=SarTestParams)
    cluster_eps_m: float = CLUSTER_EPS_M
    centre_offset_m: float = DEFAULT_CENTRE_OFFSET_M
    cluster_score: str = "sum"
    ahead_only: bool = False

    def __post_init__(self) -> None:
        if not 0.0 < self.cfar_pfa < 1.0:
            raise ZendarError(f"ChainParams.cfar_pfa must lie in (0, 1), got {self.cfar_pfa!r}")
        if not self.cluster_eps_m > 0.0:
            raise ZendarError(f"ChainParams.cluster_eps_m must be > 0 m, got {self.cluster_eps_m!r}")
        if not np.isfinite(self.centre_offset_m):
            raise ZendarError(f"ChainParams.centre_offset_m must be a finite number of metres, got {self.centre_offset_m!r}")
        if self.cluster_score not in CLUSTER_SCORES:
            raise ZendarError(f"ChainParams.cluster_score must be one of {CLUSTER_SCORES}, got {self.cluster_score!r}")

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict (recorded in the predictions' ``meta``)."""
        return {**asdict(self), "sar": self.sar.to_json(), "cfar": "CA, local maxima"}
