"""Bounded text: strings that come from outside (bags, files, plug-ins) are clipped before they are
echoed into error messages, CSV cells, summaries or ``/diagnostics``."""
from __future__ import annotations

#: Longest text kept from an outside string (characters).
MAX_TEXT = 500
MARKER = "...[{n} more characters]"


def clip(text: str, limit: int = MAX_TEXT) -> str:
    """``text`` itself, or its first ``limit`` characters and a marker naming how many were cut."""
    if len(text) <= limit:
        return text
    return text[:limit] + MARKER.format(n=len(text) - limit)
