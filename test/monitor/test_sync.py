"""StampSynchronizer: pairing by header stamp, waiting, sample-and-hold, overflow."""
from __future__ import annotations

import numpy as np
import pytest

from noise_monitor.monitor import StampSynchronizer

MS = 1_000_000


def test_exact_pair_when_metadata_came_first():
    s = StampSynchronizer(tolerance_s=0.005, wait_s=0.1)
    assert s.add_metadata(100 * MS, "m100") == []
    (m,) = s.add_image(102 * MS, "img", now_ns=0)
    assert m.metadata == "m100" and m.metadata_age_s == 0.002


def test_image_waits_for_late_metadata():
    s = StampSynchronizer(tolerance_s=0.005, wait_s=0.1)
    assert s.add_image(200 * MS, "img", now_ns=0) == []
    assert s.poll(50 * MS) == []
    (m,) = s.add_metadata(200 * MS, "m200")
    assert (m.image, m.metadata, m.metadata_age_s) == ("img", "m200", 0.0)
    assert s.poll(10**9) == []


def test_timeout_releases_with_latest_older_metadata_or_none():
    s = StampSynchronizer(tolerance_s=0.001, wait_s=0.1)
    assert s.add_image(50 * MS, "first", now_ns=0) == []
    (m,) = s.poll(100 * MS)
    assert m.metadata is None and m.metadata_age_s is None
    s.add_metadata(100 * MS, "old")
    s.add_metadata(900 * MS, "future")
    s.add_image(500 * MS, "img", now_ns=0)
    (m,) = s.poll(100 * MS)
    assert m.metadata == "old" and abs(m.metadata_age_s - 0.4) < 1e-9  # held, the caller judges the age


def test_pending_overflow_releases_oldest_first():
    s = StampSynchronizer(tolerance_s=0.001, wait_s=10.0, max_pending=2)
    out = [s.add_image(i * 100 * MS, f"img{i}", now_ns=0) for i in range(4)]
    assert [len(o) for o in out] == [0, 0, 1, 1]
    assert [o[0].image for o in out[2:]] == ["img0", "img1"]


def test_no_wait_pairs_immediately():
    s = StampSynchronizer(tolerance_s=0.001, wait_s=0.0)
    (m,) = s.add_image(5 * MS, "img", now_ns=0)
    assert m.metadata is None


def test_gap_counter_infers_lost_frames_from_stamp_gaps(rng):
    from noise_monitor.monitor import GapCounter

    period = 33_333_333
    arrived = [i for i in range(200) if i < 20 or rng.random() > 0.4]  # ~40 % lost after warm-up
    jitter = rng.integers(-500_000, 500_000, 200)
    counter = GapCounter()
    lost = sum(counter.observe(i * period + int(jitter[i])) for i in arrived)
    assert lost < 200 - len(arrived) - (200 - 1 - arrived[-1])  # the last intervals are judged at the end
    lost += counter.flush()
    assert lost == 200 - len(arrived) - (200 - 1 - arrived[-1])
    assert counter.observe(arrived[-1] * period - 10**6) == 0 and counter.flush() == 0  # old stamps count nothing


def test_gap_counter_with_the_expected_rate_counts_regular_losses(rng):
    from noise_monitor.monitor import GapCounter

    period = 33_333_333
    arrived = [i for i in range(300) if i % 2 == 0 or i < 10]  # every other frame lost, regularly
    jitter = rng.integers(-500_000, 500_000, 300)
    stamps = [i * period + int(jitter[i]) for i in arrived]
    inferred = GapCounter()
    assert sum(inferred.observe(t) for t in stamps) < 40  # of 144: once the window is full it looks like 15 Hz
    exact = GapCounter(expected_rate_hz=30.0)
    lost = sum(exact.observe(t) for t in stamps)
    assert lost + exact.observe(stamps[-1] + 10**9 * 5) == 300 - len(arrived) - 1  # a pause judges what waits
    assert exact.flush() == 0  # and is not a loss itself
    with pytest.raises(ValueError, match="expected_rate_hz"):
        GapCounter(expected_rate_hz=-1.0)


def test_gap_counter_counts_no_loss_where_frames_came_late_or_in_bursts(rng):
    """Every frame delivered, none lost (the node's audit, 2026-12-04: a burst of 10 images 3 ms apart at start-up
    made the period 3 ms and every later 100 ms interval 32 lost frames: 524 counted for 40 delivered; 12,550 after
    a burst of 240). Now a burst is not the period, and short intervals beside a gap fill it."""
    from noise_monitor.monitor import GapCounter

    period = 100_000_000

    def count(stamps: list[int], **kw) -> int:
        counter = GapCounter(**kw)
        return sum(counter.observe(s) for s in stamps) + counter.flush()

    burst_then_steady = [k * 3_000_000 for k in range(10)] + [27_000_000 + k * period for k in range(1, 31)]
    assert count(burst_then_steady) == 0
    steady = [k * period + int(j) for k, j in enumerate(rng.integers(-2_000_000, 2_000_000, 60))]
    buffered = steady[:20] + [steady[24] + k * 2_000_000 for k in range(5)] + steady[25:]  # held back, then a burst
    assert count(buffered) == 0 and count(buffered, expected_rate_hz=10.0) == 0
    late = list(steady)
    late[30] += 70_000_000  # one frame stamped 0.7 periods late: 1.7 then 0.3 periods
    early = list(steady)
    early[40] -= 70_000_000
    assert count(late) == 0 and count(early) == 0
    lost = steady[:10] + steady[13:40] + steady[41:]  # 3 then 1 really missing, beside the late and early frames
    assert count(lost) == 4 and count(lost, expected_rate_hz=10.0) == 4
    unpaced = np.cumsum(rng.exponential(300_000, 200)).astype(int)  # a loop publishing as fast as it can,
    assert count([int(s) for s in unpaced[rng.random(200) > 0.8]]) == 0  # most lost: no frame rate, no count
    counter = GapCounter()
    assert sum(counter.observe(int(s)) for s in unpaced) == 0 and len(counter.pending) <= counter.delay  # bounded
    repeated = steady[:5] + [steady[4]] * 3 + steady[5:]  # a driver publishing one frame three more times
    counter = GapCounter()
    assert sum(counter.observe(s) for s in repeated) + counter.flush() == 0 and counter.implausible == 3


def test_stamps_that_jump_back_keep_pairing():
    """A bag played in a loop, a sim-time restart or a camera clock reset: the stamps jump back a day. The history
    forgets the metadata that came first, not the lowest stamp: before (2026-11-29) each new metadata was the
    lowest stamp and was dropped at once, so every later image read "metadata missing" (0 of 100 paired)."""
    sync: StampSynchronizer[str, str] = StampSynchronizer(tolerance_s=0.01, wait_s=0.05, history=8)
    day, period = 86_400 * 10**9, 33_333_333
    for base in (2 * day, day):  # the second pass a day earlier
        paired = 0
        for k in range(100):
            stamp = base + k * period
            sync.add_metadata(stamp, f"m{stamp}")
            out = sync.add_image(stamp, f"i{stamp}", now_ns=k)
            paired += len(out) == 1 and out[0].metadata == f"m{stamp}"
        assert paired == 100
    assert len(sync._stamps) == 8 and day <= min(sync._stamps) <= max(sync._stamps) < 2 * day  # the newest pass


def test_gap_counter_counts_losses_while_it_learns_the_period():
    """Frames lost among the first stamps (a short bag): counted once judged, ``delay`` intervals later or at the
    stream's end (until 2026-11-29 the warm-up's gaps were never counted: 1 of 4 lost frames in a fleet audit's
    bag)."""
    from noise_monitor.monitor import GapCounter

    period = 33_333_333
    arrived = [0, 1, 3, 4, 7, 8, 9, 10, 11, 12, 13, 16, 17, 18, 19]  # 2, 5, 6 lost early; 14, 15 later
    counter = GapCounter()
    assert sum(counter.observe(i * period) for i in arrived) == 0  # 14 intervals: none judged yet
    assert counter.flush() == 5
    early = GapCounter(delay=4)
    counts = [early.observe(i * period) for i in arrived]
    assert counts[8] == 3 and sum(counts) + early.flush() == 5  # the 8th interval (frame 11) judges the first three
