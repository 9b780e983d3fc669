"""The stated black level against the image: a pedestal stated above the camera's leaves its dark pixels far below
zero, which the monitor reports (with a bound of the camera's black level); a right one, dead pixels or no stated
black level never do."""
from __future__ import annotations

import numpy as np
import pytest

from noise_monitor.monitor.black_level import CONTRADICTED_FRACTION, check_black_level

SIGMA = 0.8  # DN of dark noise (EV76C661 at 0 dB)


def dark_scene(rng: np.random.Generator, camera_black: float, stated: float) -> np.ndarray:
    """A 256 x 256 image, a quarter of it at black (the rest at 60 DN), as read with ``stated`` taken off."""
    clean = np.full((256, 256), 60.0)
    clean[:128, :128] = 0.0
    raw = np.clip(np.rint(camera_black + clean + rng.normal(0.0, SIGMA, clean.shape)), 0.0, 255.0)
    return (raw - stated).astype(np.float32)


@pytest.mark.parametrize("camera_black", [0.0, 3.0, 6.0])
def test_a_black_level_stated_above_the_cameras_is_contradicted_and_bounded(camera_black: float) -> None:
    """Stated 16 DN over a camera at 0 / 3 / 6 DN: a quarter of the pixels read 10-16 DN below the statement, far
    beyond the dark noise; the image bounds the camera's black level from above, within 4 sigmas (+ the rounding) of
    the truth."""
    check = check_black_level(dark_scene(np.random.default_rng(1), camera_black, 16.0), 16.0, SIGMA)
    assert check is not None and check.contradicted
    assert check.below_pct == pytest.approx(25.0, abs=0.5)
    assert check.upper_dn is not None and camera_black <= check.upper_dn <= camera_black + 4 * SIGMA + 0.5
    assert "the camera's is lower" in check.message()


def test_a_right_black_level_dead_pixels_or_none_stated_are_not_contradicted() -> None:
    rng = np.random.default_rng(2)
    right = check_black_level(dark_scene(rng, 16.0, 16.0), 16.0, SIGMA)
    assert right is not None and not right.contradicted and right.below_pct == 0.0
    dead = dark_scene(rng, 16.0, 16.0)
    dead.ravel()[rng.choice(dead.size, int(0.5 * CONTRADICTED_FRACTION * dead.size), replace=False)] = -16.0
    assert not check_black_level(dead, 16.0, SIGMA).contradicted  # raw zeros of dead pixels
    # the dark noise twice the model's (a gain stated 6 dB low) stays inside the limit
    assert not check_black_level(dark_scene(rng, 16.0, 16.0) * 2.0, 16.0, SIGMA).contradicted
    assert check_black_level(dark_scene(rng, 0.0, 0.0), 0.0, SIGMA) is None
    # a black level stated within the dark noise of the camera's cannot be told apart
    assert not check_black_level(dark_scene(rng, 14.0, 16.0), 16.0, SIGMA).contradicted
