"""Temporal filter and the xi alarm state machine (threshold, hysteresis, minimum durations)."""
from __future__ import annotations

from dataclasses import dataclass

CAUSE_IMAGE_NOISIER = "image noisier than the model predicts (unexpected noise source)"
CAUSE_MODEL_NOISIER = "model predicts more noise than the image shows (metadata wrong or sensor changed)"


def cause_of(xi: float) -> str:
    """The plain-language cause of a xi = sigma_model - sigma_image deviation."""
    return CAUSE_IMAGE_NOISIER if xi < 0 else CAUSE_MODEL_NOISIER


class EmaFilter:
    """Exponential moving average per key; the first value initialises."""

    def __init__(self, alpha: float) -> None:
        self.alpha = alpha
        self.state: dict[str, float] = {}

    def update(self, values: dict[str, float]) -> dict[str, float]:
        for key, v in values.items():
            prev = self.state.get(key)
            self.state[key] = v if prev is None else prev + self.alpha * (v - prev)
        return {k: self.state[k] for k in values}

    def reset(self) -> None:
        self.state.clear()


@dataclass
class AlarmState:
    """Externally visible state: ``active`` alarm, its ``cause`` and the frame counters."""

    active: bool = False
    cause: str | None = None
    sign: int = 0
    above: int = 0  # consecutive frames with |xi| > threshold (while inactive)
    below: int = 0  # consecutive frames with |xi| < threshold - hysteresis (while active)
    episodes: int = 0

    @property
    def name(self) -> str:
        if self.active:
            return "clearing" if self.below else "alarm"
        return "pending" if self.above else "ok"


class XiAlarm:
    """Raises after ``min_frames`` consecutive frames with |xi| > threshold, clears after ``clear_frames``
    consecutive frames with |xi| < threshold - hysteresis. The cause follows the sign of xi."""

    def __init__(self, threshold: float, hysteresis: float, min_frames: int, clear_frames: int) -> None:
        self.threshold = threshold
        self.clear_level = threshold - hysteresis
        self.min_frames = min_frames
        self.clear_frames = clear_frames
        self.state = AlarmState()

    def update(self, xi: float) -> AlarmState:
        s = self.state
        if not s.active:
            s.above = s.above + 1 if abs(xi) > self.threshold else 0
            if s.above >= self.min_frames:
                s.active, s.above, s.below, s.episodes = True, 0, 0, s.episodes + 1
                s.sign, s.cause = (-1 if xi < 0 else 1), cause_of(xi)
        else:
            if abs(xi) > self.threshold:
                s.sign, s.cause = (-1 if xi < 0 else 1), cause_of(xi)
            s.below = s.below + 1 if abs(xi) < self.clear_level else 0
            if s.below >= self.clear_frames:
                s.active, s.cause, s.sign, s.below = False, None, 0, 0
        return s
