"""Domain constants shared by the physics, the estimator, the monitor and the lab (defined once here)."""
from __future__ import annotations

#: Top of the 8-bit DN scale every image is brought to.
DN_MAX = 255.0
#: The paper's noise sources: photon shot noise, dark-current shot noise, readout noise.
PAPER_EFFECTS = ("pn", "dcsn", "rn")
#: Noise model modes: the physical camera (one pass, clipped once) and the paper's training protocol.
MODES = ("joint", "sequential")
#: Box filter (pixels) estimating a patch's clean intensity map for model predictions.
SMOOTH_KERNEL = 5
#: Smallest patch edge (pixels) the estimator and the node's patch_size take (two 8x8 blocks per side).
MIN_PATCH = 16
