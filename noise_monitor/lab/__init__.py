"""The lab: measure the noise in a bag independently of the model, compare with the model, diagnose and
add missing effects, report (``noise-monitor analyze``)."""
from .analyze import analyze, parse_add_effect
from .compare import Comparison, by_condition, rms_error
from .diagnose import Candidate, Diagnosis, diagnose, fit
from .measure import Measurements, SegmentTolerance, measure_frames

__all__ = [
    "Candidate", "Comparison", "Diagnosis", "Measurements", "SegmentTolerance", "analyze", "by_condition", "diagnose", "fit",
    "measure_frames", "parse_add_effect", "rms_error",
]
