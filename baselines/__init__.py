"""The paper's reference baselines (Mostajabi et al. 2020, §2.3, §4) and the main command ``zendar-bench``.

Installed under the import name ``zendar_baselines`` (a bare ``baselines`` module already exists on
PyPI). On top of the detection chain (:mod:`zendar_dataset.detection`: CFAR, DOA, the SAR
static-scene test, clusters), in four wings:

- ``classical``: the CFAR baseline (Table 1, row 1) and the fit of the chain's constants;
- ``labels``: automatic labels (per range-Doppler frame a dynamic-object mask grown around CFAR points
  that the SAR test calls moving, with the paper's "uncertain" class), manual-label masks, their
  quality, the semi-supervised split and the versioned mask store;
- ``cnn``: the CNN detectors (FPN-ResNet-34, zoom-out DenseNet-37 and -67), their inputs, training,
  checkpoints and inference;
- ``bench``: ``zendar-bench``, which runs all of it and writes Table 1.
"""

from zendar_dataset import __version__

__all__ = ["__version__"]
