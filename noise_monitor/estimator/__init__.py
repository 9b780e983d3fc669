"""The Full-Meta estimator family: physics-anchored noise sources, a learned image-noise measurement, xi.

``load(name="full_meta", device="auto")`` returns an estimator with ``predict(patches_dn, metas)`` ->
dict of arrays in DN: ``pn``, ``dcsn``, ``rn``, ``xi``, ``total`` (plus ``sigma_model``,
``sigma_image``), and attributes ``patch_size`` and ``name``.
"""
from .inference import NAMES, FullMetaEstimator, PaperEstimator, load

__all__ = ["NAMES", "FullMetaEstimator", "PaperEstimator", "load"]
