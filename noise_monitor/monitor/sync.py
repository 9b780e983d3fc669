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


#: Stamp intervals needed before the frame period is inferred from them.
WARMUP_INTERVALS = 8
#: A stream has a frame rate when this share of its recent intervals lies within this fraction of a period
#: of a whole number of periods (a camera with its jitter and losses does; a loop publishing as fast as it can
#: does not, and its gaps are not counted).
REGULAR_SHARE, REGULAR_TOLERANCE = 0.75, 0.25
#: Shortest frame period believed from header stamps (10 kHz): closer stamps are a bogus clock, not losses.
MIN_PERIOD_NS = 100_000


class GapCounter:
    """Counts images that never arrived (lost in transport or by a full subscriber queue), inferred from
    header-stamp gaps: an interval of about k frame periods means k - 1 missing frames, unless the frames came
    late rather than never: intervals shorter than half a period right before or after a gap (a frame stamped
    early, a driver's buffer delivered in a burst and stamped on arrival) fill it, one frame each. Each interval
    is judged ``delay`` intervals after it arrived, with the period of the stamps around it: the lower quartile of
    the recent intervals at least half their median (bursts are not the period; a few losses do not lengthen it),
    so a burst at start-up does not make every later interval a gap. Gaps longer than ``pause_s`` are a paused
    stream, not losses. Inferred, it undercounts regular losses (every other frame lost looks like half the
    rate), and counts nothing while the recent intervals are no whole numbers of a period (no frame rate to
    speak of: :data:`REGULAR_SHARE`); ``expected_rate_hz`` (the camera's configured
    rate) makes the period known and the count exact. After a pause or a stamp jumping back the period is learnt
    again. Intervals shorter than :data:`MIN_PERIOD_NS` (a repeated stamp, stamps 1 ns apart) are a bogus
    clock: counted in ``implausible``, never as losses. :meth:`flush` judges the intervals still waiting (the
    stream's end)."""

    def __init__(self, window: int = 64, pause_s: float = 1.0, expected_rate_hz: float = 0.0,
                 delay: int = 16) -> None:
        if not 0 <= expected_rate_hz <= 1e9 / MIN_PERIOD_NS:
            raise ValueError(f"expected_rate_hz must be in [0, {1e9 / MIN_PERIOD_NS:g}] Hz, got {expected_rate_hz}")
        self.implausible = 0
        self.intervals: deque[int] = deque(maxlen=window)  # the recent ones, for the period
        self.pending: deque[int] = deque()  # not judged yet
        self.delay = delay
        self.last_ns: int | None = None
        self.pause_ns = int(pause_s * 1e9)
        self.period_ns = 1e9 / expected_rate_hz if expected_rate_hz > 0 else None
        if self.period_ns is not None:
            self.pause_ns = max(self.pause_ns, int(4 * self.period_ns))
        self._credit = 0  # short intervals just before the next one judged, not yet filling a gap
        self._used_ahead = 0  # the first pending intervals, short, already filling a gap judged before them

    def observe(self, stamp_ns: int) -> int:
        """Record an image stamp; returns the number of missing frames judged now (in the gap ``delay``
        intervals back; at a pause or a stamp jumping back, in all the intervals still waiting)."""
        last, self.last_ns = self.last_ns, stamp_ns
        if last is None:
            return 0
        dt = stamp_ns - last
        if 0 <= dt < MIN_PERIOD_NS:
            self.implausible += 1
            self.last_ns = last  # the frame period runs from the first of such stamps
            return 0
        if dt < 0 or dt > self.pause_ns:  # a reset clock or a paused stream: what waits is judged, no gap here,
            lost = self.flush()  # and the period is learnt again (a driver restarted at another rate)
            self.intervals.clear()
            return lost
        self.intervals.append(dt)
        self.pending.append(dt)
        return self._judge(len(self.pending) - self.delay)

    def flush(self) -> int:
        """Judge every interval still waiting (the end of the stream or of a run of it)."""
        lost = self._judge(len(self.pending))
        self._credit = 0
        return lost

    def _period(self) -> float | None:
        """The frame period (ns); None while too few intervals are known, 0.0 where the stamps have no rate."""
        if self.period_ns is not None:
            return self.period_ns
        if len(self.intervals) < WARMUP_INTERVALS:
            return None
        recent = np.asarray(self.intervals, dtype=float)
        period = float(np.percentile(recent[recent >= 0.5 * np.median(recent)], 25))
        multiple = recent / period
        on_grid = (multiple >= 0.5) & (np.abs(multiple - np.round(multiple)) <= REGULAR_TOLERANCE)
        return period if np.mean(on_grid) >= REGULAR_SHARE else 0.0  # 0: no frame rate, no count

    def _judge(self, n: int) -> int:
        period = self._period() if n > 0 else None
        if period is None:  # too few intervals yet: they wait
            return 0
        if period == 0.0:  # no frame rate to judge them by: they count nothing
            for _ in range(n):
                self.pending.popleft()
            self._used_ahead, self._credit = max(self._used_ahead - n, 0), 0
            return 0
        lost = 0
        for _ in range(n):
            k = int(round(self.pending.popleft() / period))
            if k == 0:  # a frame early or delivered in a burst
                if self._used_ahead:
                    self._used_ahead -= 1
                else:
                    self._credit += 1
                continue
            missing, self._credit = max(k - 1 - self._credit, 0), 0
            for dt in list(self.pending)[self._used_ahead:]:  # the burst right after the gap
                if missing == 0 or round(dt / period) != 0:
                    break
                missing, self._used_ahead = missing - 1, self._used_ahead + 1
            lost += missing
        return lost
