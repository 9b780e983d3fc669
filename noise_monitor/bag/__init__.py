"""Bags: reading (rosbags), writing, synthetic field campaigns, replay through the monitor, playback."""
from .errors import BagError

__all__ = ["BagError"]
