"""A small mask network and a hand-made moving-target task for the training tests.

The task imitates §4.2 on 2 stacked maps (K = 2, one antenna): static reflectors are bright at the
same cell in both maps, a moving one is bright at one cell in the newest map and at a shifted cell
in the older one. The mask marks the moving cell of the newest map 1 and its four neighbours 2
(uncertain), so only the temporal difference separates the classes.
"""

from __future__ import annotations

import numpy as np
from torch import nn

N_RANGE, N_DOPPLER = 16, 8
TARGET_AMPLITUDE = 3.0


class TinyMaskNet(nn.Module):
    """Conv 3×3 → ReLU → conv 1×1: logits ``[B, 1, R, D]`` for input ``[B, C, R, D]``."""

    def __init__(self, in_channels: int, width: int = 8) -> None:
        super().__init__()
        self.architecture = {"name": "tiny-mask-net", "in_channels": in_channels, "width_scale": width / 8}
        self.features = nn.Conv2d(in_channels, width, kernel_size=3, padding=1)
        self.head = nn.Conv2d(width, 1, kernel_size=1)

    def forward(self, inputs):
        return self.head(self.features(inputs).relu())


def moving_target_task(n_samples: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Stacked inputs float32 ``[N, 2, R, D]`` (old map, newest map) and uint8 masks ``[N, R, D]``."""
    rng = np.random.default_rng(seed)
    inputs = rng.normal(0.0, 0.3, size=(n_samples, 2, N_RANGE, N_DOPPLER)).astype(np.float32)
    masks = np.zeros((n_samples, N_RANGE, N_DOPPLER), dtype=np.uint8)
    for index in range(n_samples):
        cells = rng.choice(N_RANGE * N_DOPPLER, size=3, replace=False)
        for cell in cells[:2]:  # static: same cell in both maps
            r, d = divmod(int(cell), N_DOPPLER)
            inputs[index, :, r, d] += TARGET_AMPLITUDE
        r, d = divmod(int(cells[2]), N_DOPPLER)
        inputs[index, 1, r, d] += TARGET_AMPLITUDE
        inputs[index, 0, (r + rng.integers(2, 4)) % N_RANGE, (d + rng.integers(1, 3)) % N_DOPPLER] += TARGET_AMPLITUDE
        for dr, dd in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            rr, ddd = r + dr, d + dd
            if 0 <= rr < N_RANGE and 0 <= ddd < N_DOPPLER:
                masks[index, rr, ddd] = 2
        masks[index, r, d] = 1
    return inputs, masks
