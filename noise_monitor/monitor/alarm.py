"""Temporal filter and the xi alarm state machine (threshold, hysteresis, evidence, minimum durations)."""
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
    above: int = 0  # consecutive frames with |filtered xi| > threshold (while inactive)
    below: int = 0  # consecutive frames with |filtered xi| < threshold - hysteresis (while active)
    episodes: int = 0
    # one-sided CUSUMs of (xi - threshold) / error and (-xi - threshold) / error (while inactive)
    evidence_pos: float = 0.0
    evidence_neg: float = 0.0

    @property
    def evidence(self) -> float:
        """The larger of the two sides' accumulated evidence (standard errors beyond the threshold)."""
        return max(self.evidence_pos, self.evidence_neg)

    @property
    def name(self) -> str:
        if self.active:
            return "clearing" if self.below else "alarm"
        return "pending" if self.above or self.evidence > 0 else "ok"


class XiAlarm:
    """The xi alarm. Raises on whichever comes first:

    - evidence: a one-sided CUSUM per sign on the per-frame xi in units of its standard error,
      S+ = max(0, S+ + (xi - threshold) / error) (S- likewise for -xi), reaching ``evidence``: a xi far
      beyond the threshold raises on one frame, one just beyond it after a few, and a xi inside the
      threshold drains the sum (0 = off);
    - count: ``min_frames`` consecutive frames with |filtered xi| > threshold.

    :meth:`restart` (a metadata step: a new view) restarts the count (the filter restarts with it) and keeps the
    evidence: it sums frames' own xi beyond the threshold, so it raises only on a frame whose own xi is beyond it,
    and a camera whose exposure steps every few frames (a sweep, auto-exposure) is judged on all of them.
    Clears after ``clear_frames`` consecutive frames with |filtered xi| < threshold - hysteresis. The cause
    follows the sign of xi.
    """

    def __init__(self, threshold: float, hysteresis: float, min_frames: int, clear_frames: int,
                 evidence: float = 0.0) -> None:
        self.threshold = threshold
        self.clear_level = threshold - hysteresis
        self.min_frames = min_frames
        self.clear_frames = clear_frames
        self.evidence = evidence
        self.state = AlarmState()

    def restart(self) -> None:
        """A new view (metadata step): the count towards raising starts again; the evidence carries on."""
        self.state.above = 0

    def _raise(self, xi: float) -> None:
        s = self.state
        s.active, s.above, s.below, s.episodes = True, 0, 0, s.episodes + 1
        s.evidence_pos = s.evidence_neg = 0.0
        s.sign, s.cause = (-1 if xi < 0 else 1), cause_of(xi)

    def update(self, xi_filtered: float, xi: float | None = None, error: float | None = None) -> AlarmState:
        """One processed frame: its filtered xi and, for the evidence, its own xi with standard error (DN)."""
        s = self.state
        if not s.active:
            s.above = s.above + 1 if abs(xi_filtered) > self.threshold else 0
            if self.evidence > 0 and xi is not None and error is not None and error > 0:
                s.evidence_pos = max(0.0, s.evidence_pos + (xi - self.threshold) / error)
                s.evidence_neg = max(0.0, s.evidence_neg + (-xi - self.threshold) / error)
                if s.evidence >= self.evidence:
                    self._raise(1.0 if s.evidence_pos >= s.evidence_neg else -1.0)
                    return s
            if s.above >= self.min_frames:
                self._raise(xi_filtered)
        else:
            if abs(xi_filtered) > self.threshold:
                s.sign, s.cause = (-1 if xi_filtered < 0 else 1), cause_of(xi_filtered)
            s.below = s.below + 1 if abs(xi_filtered) < self.clear_level else 0
            if s.below >= self.clear_frames:
                s.active, s.cause, s.sign, s.below = False, None, 0, 0
        return s
