"""Diagnostic status levels and the middleware-neutral status report of the monitor."""
from __future__ import annotations

from dataclasses import dataclass, field

from ..text import clip

OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_NAMES: dict[int, str] = {OK: "OK", WARN: "WARN", ERROR: "ERROR", STALE: "STALE"}
#: The texts a frame's status carries: which measurement drove its xi (``xi_measurement``: the single image's reading,
#: a still hold's frame differences, what the image proves where texture hides the noise) and what restarted a still
#: hold's frame-difference measurement on it (``hold_event``; several joined by ", ").
XI_MEASUREMENTS = ("image", "temporal", "bound")
HOLD_EVENTS = ("noise changed", "light stepped")
HOLD_EVENT_SEPARATOR = ", "


@dataclass(frozen=True)
class StatusReport:
    """One diagnostic status, middleware-neutral (values are strings, numbers as numeric strings)."""

    level: int
    name: str
    message: str
    hardware_id: str
    values: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.level not in LEVEL_NAMES:
            raise ValueError(f"diagnostic level must be one of {sorted(LEVEL_NAMES)}, got {self.level!r}")
        bad = [k for k, v in self.values.items() if not isinstance(v, str)]
        if bad:
            raise ValueError(f"diagnostic values must be strings: {', '.join(bad)}")
        # texts may echo bag or message contents: bounded, with a marker where cut
        for name in ("name", "message", "hardware_id"):
            object.__setattr__(self, name, clip(getattr(self, name)))
        object.__setattr__(self, "values", {clip(k, 200): clip(v) for k, v in self.values.items()})
