"""CNN detectors of paper §4.2: per-cell dynamic-object masks from stacked range-Doppler maps."""
