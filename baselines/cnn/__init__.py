"""The CNN detectors of paper §4.2: models (a name -> builder registry), input maps, training samples,
training with checkpoints, inference."""
