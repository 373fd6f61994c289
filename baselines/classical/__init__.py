"""The classical baseline of Table 1 (CFAR through the detection chain) and the fit of the chain's constants
on a training split."""
