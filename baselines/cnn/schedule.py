"""A training phase's schedule (paper §4.1–4.2: Adam with a constant learning rate)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Schedule:
    """One training phase: Adam with a constant learning rate, at most ``epochs`` epochs.

    Attributes
    ----------
    lr : float
        Adam's learning rate.
    batch_size : int
        The global batch (split evenly over processes).
    epochs : int
        Epochs at most.
    patience : int or None
        Early stopping: the phase ends once this many epochs in a row brought no lower validation
        loss than the best so far. None runs every epoch.
    """

    lr: float
    batch_size: int
    epochs: int
    patience: int | None = None
