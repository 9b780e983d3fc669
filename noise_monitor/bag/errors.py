"""The one exception type of the bag package."""
from __future__ import annotations


class BagError(ValueError):
    """A bag cannot be read or written (corrupt, truncated, empty, missing topics, bad arguments)."""
