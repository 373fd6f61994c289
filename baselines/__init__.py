"""The paper's reference baselines (Mostajabi et al. 2020, §2.3, §4) and the main command ``zendar-bench``.

Installed under the import name ``zendar_baselines`` (a bare ``baselines`` module already exists on
PyPI). The pieces, bottom up:

- the SAR static-scene test and the CFAR baseline (Table 1, row 1);
- automatic labels: per range-Doppler frame a dynamic-object mask grown around CFAR points that the SAR
  test calls moving, with the paper's "uncertain" class, written to a versioned side store;
- the semi-supervised split of the training scenes into a labelled and an unlabelled part;
- the CNN detectors (FPN-ResNet-34, zoom-out DenseNet-37 and -67), their training and inference;
- ``zendar-bench``, which runs all of it and writes Table 1.
"""

from zendar_dataset import __version__

__all__ = ["__version__"]
