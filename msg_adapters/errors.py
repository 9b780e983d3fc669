"""The one exception type of msg_adapters."""
from __future__ import annotations


class AdapterError(ValueError):
    """A ROS message cannot be converted (unsupported encoding, inconsistent size, bad value)."""
