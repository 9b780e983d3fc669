"""A small header-stamp synchroniser for images and their metadata (no message_filters needed).

An image is paired with the metadata whose stamp is within ``tolerance_s``. If none has arrived, the
image waits up to ``wait_s`` (metadata may come slightly later); then it is released with the latest
metadata stamped before it (sample-and-hold; the caller judges its age) or with none.
"""
from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass
from typing import Generic, TypeVar

import numpy as np

T = TypeVar("T")
M = TypeVar("M")


def nearest_within(stamps: list[int], stamp_ns: int, tolerance_ns: int) -> int | None:
    """Index of the sorted ``stamps`` entry nearest ``stamp_ns`` within the tolerance, else None."""
    i = bisect.bisect_right(stamps, stamp_ns)
    near = [j for j in (i - 1, i) if 0 <= j < len(stamps) and abs(stamps[j] - stamp_ns) <= tolerance_ns]
    return min(near, key=lambda j: abs(stamps[j] - stamp_ns)) if near else None


def match_stamp(stamps: list[int], stamp_ns: int, tolerance_ns: int) -> int | None:
    """The metadata matching rule of node, replay and lab: the stamp nearest the image stamp within the
    tolerance, else the latest one before it (sample-and-hold; the monitor judges its age), else None."""
    near = nearest_within(stamps, stamp_ns, tolerance_ns)
    if near is not None:
        return near
    i = bisect.bisect_right(stamps, stamp_ns)
    return i - 1 if i else None


@dataclass(frozen=True)
class Matched(Generic[T, M]):
    """An image payload with the metadata chosen for it (``None`` if there was none)."""

    stamp_ns: int
    image: T
    received_ns: int
    metadata: M | None = None
    metadata_stamp_ns: int | None = None

    @property
    def metadata_age_s(self) -> float | None:
        """Image stamp minus metadata stamp (s); None without metadata."""
        return None if self.metadata_stamp_ns is None else (self.stamp_ns - self.metadata_stamp_ns) / 1e9


class StampSynchronizer(Generic[T, M]):
    """Pairs images with metadata by header stamp; thread-unsafe (call from one executor thread)."""

    def __init__(self, tolerance_s: float, wait_s: float, history: int = 64, max_pending: int = 4) -> None:
        if tolerance_s < 0 or wait_s < 0 or history < 1 or max_pending < 1:
            raise ValueError("tolerance_s and wait_s must be >= 0, history and max_pending >= 1")
        self.tol_ns = int(tolerance_s * 1e9)
        self.wait_ns = int(wait_s * 1e9)
        self.history = history
        self._stamps: list[int] = []  # sorted metadata stamps and their values
        self._values: list[M] = []
        self._arrivals: deque[int] = deque()  # the stamps in the order they came: the first to come goes first
        self.pending: deque[tuple[int, T, int]] = deque()
        self.max_pending = max_pending

    def _at(self, i: int | None) -> tuple[int, M] | None:
        return None if i is None else (self._stamps[i], self._values[i])

    def _exact(self, stamp_ns: int) -> tuple[int, M] | None:
        return self._at(nearest_within(self._stamps, stamp_ns, self.tol_ns))

    def _held(self, stamp_ns: int) -> tuple[int, M] | None:
        return self._at(match_stamp(self._stamps, stamp_ns, self.tol_ns))

    @staticmethod
    def _pair(stamp: int, image: T, received: int, meta: tuple[int, M] | None) -> Matched[T, M]:
        return Matched(stamp, image, received, meta[1] if meta else None, meta[0] if meta else None)

    def add_metadata(self, stamp_ns: int, metadata: M) -> list[Matched[T, M]]:
        """Store metadata; returns the waiting images it completes."""
        i = bisect.bisect_right(self._stamps, stamp_ns)
        self._stamps.insert(i, stamp_ns)
        self._values.insert(i, metadata)
        self._arrivals.append(stamp_ns)
        if len(self._stamps) > self.history:  # forget the one that came first (after stamps jumped back, not the
            j = bisect.bisect_left(self._stamps, self._arrivals.popleft())  # lowest stamp: the newest message)
            del self._stamps[j], self._values[j]
        out: list[Matched[T, M]] = []
        keep: deque[tuple[int, T, int]] = deque()
        for stamp, image, received in self.pending:
            if abs(stamp - stamp_ns) <= self.tol_ns:
                out.append(self._pair(stamp, image, received, (stamp_ns, metadata)))
            else:
                keep.append((stamp, image, received))
        self.pending = keep
        return out

    def add_image(self, stamp_ns: int, image: T, now_ns: int) -> list[Matched[T, M]]:
        """Returns the image paired at once, or nothing while it waits (plus any overflowed image)."""
        exact = self._exact(stamp_ns)
        if exact is not None or self.wait_ns == 0:
            return [self._pair(stamp_ns, image, now_ns, exact or self._held(stamp_ns))]
        self.pending.append((stamp_ns, image, now_ns))
        out = []
        while len(self.pending) > self.max_pending:
            stamp, img, received = self.pending.popleft()
            out.append(self._pair(stamp, img, received, self._held(stamp)))
        return out

    def poll(self, now_ns: int) -> list[Matched[T, M]]:
        """Release images that waited ``wait_s`` without matching metadata."""
        out = []
        while self.pending and now_ns - self.pending[0][2] >= self.wait_ns:
            stamp, image, received = self.pending.popleft()
            out.append(self._pair(stamp, image, received, self._held(stamp)))
        return out

    def clear(self) -> None:
        self._stamps.clear()
        self._values.clear()
        self._arrivals.clear()
        self.pending.clear()


#: Stamp intervals seen before the frame period is inferred (their gaps are counted once it is).
WARMUP_INTERVALS = 8
#: Shortest frame period believed from header stamps (10 kHz): closer stamps are a bogus clock, not losses.
MIN_PERIOD_NS = 100_000


class GapCounter:
    """Counts images that never arrived (lost in transport or by a full subscriber queue), inferred from
    header-stamp gaps: the frame period is the lower quartile of the recent stamp intervals (robust to
    a few bursts), and an interval of about k periods means k - 1 missing frames. Gaps longer than
    ``pause_s`` are a paused stream, not losses. Inferred, it undercounts regular losses (every other
    frame lost looks like half the rate); ``expected_rate_hz`` (the camera's configured rate) makes the
    period known and the count exact. An inferred period below :data:`MIN_PERIOD_NS` (stamps 1 ns apart)
    is implausible: such intervals are counted in ``implausible``, never as losses."""

    def __init__(self, window: int = 64, pause_s: float = 1.0, expected_rate_hz: float = 0.0) -> None:
        if not 0 <= expected_rate_hz <= 1e9 / MIN_PERIOD_NS:
            raise ValueError(f"expected_rate_hz must be in [0, {1e9 / MIN_PERIOD_NS:g}] Hz, got {expected_rate_hz}")
        self.implausible = 0
        self.intervals: deque[int] = deque(maxlen=window)
        self._warm = False  # the period has been inferred once (the warm-up gaps counted)
        self.last_ns: int | None = None
        self.pause_ns = int(pause_s * 1e9)
        self.period_ns = 1e9 / expected_rate_hz if expected_rate_hz > 0 else None
        if self.period_ns is not None:
            self.pause_ns = max(self.pause_ns, int(4 * self.period_ns))

    def observe(self, stamp_ns: int) -> int:
        """Record an image stamp; returns the number of frames missing just before it."""
        last, self.last_ns = self.last_ns, stamp_ns
        if last is None or stamp_ns <= last or stamp_ns - last > self.pause_ns:
            return 0
        dt = stamp_ns - last
        if self.period_ns is not None:
            return max(int(round(dt / self.period_ns)) - 1, 0)
        self.intervals.append(dt)
        if len(self.intervals) < WARMUP_INTERVALS:
            return 0
        period = float(np.percentile(self.intervals, 25))
        if period < MIN_PERIOD_NS:
            self.implausible += 1
            return 0
        # the first time the period is known, the gaps seen while learning it count too
        gaps = self.intervals if len(self.intervals) == WARMUP_INTERVALS and not self._warm else (dt,)
        self._warm = True
        return sum(max(int(round(g / period)) - 1, 0) for g in gaps)
