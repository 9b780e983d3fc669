"""The per-frame monitoring pipeline shared by the live node and the bag replay."""
from .alarm import CAUSE_IMAGE_NOISIER, CAUSE_MODEL_NOISIER, EmaFilter, XiAlarm, cause_of
from .config import DESCRIPTIONS, MonitorConfig, read_ros_params
from .patches import PatchSelection, select_patches
from .pipeline import Estimator, Frame, FrameResult, Monitor
from .sync import GapCounter, Matched, StampSynchronizer

__all__ = [
    "CAUSE_IMAGE_NOISIER", "CAUSE_MODEL_NOISIER", "DESCRIPTIONS", "EmaFilter", "Estimator", "Frame", "FrameResult", "GapCounter",
    "Matched", "Monitor", "MonitorConfig", "PatchSelection", "StampSynchronizer", "XiAlarm", "cause_of", "read_ros_params", "select_patches",
]
