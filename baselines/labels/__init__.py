"""Labels for the CNNs: automatic masks (CFAR + SAR test + segment growth, paper §2.3), manual-label masks,
their quality, the semi-supervised split and the versioned mask store."""
