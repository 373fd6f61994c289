"""A training phase's schedule (paper §4.1–4.2: Adam with a constant learning rate)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Schedule:
    """One training phase: Adam with a constant learning rate."""

    lr: float
    batch_size: int
    epochs: int
