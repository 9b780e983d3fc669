"""Estimator test helpers."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest


@pytest.fixture
def seeded_images() -> Callable[..., list[np.ndarray]]:
    """Check an image generator ``(rng, n, size=...)``: the same seed gives the same images, each a 96 px
    float32 image on the DN scale with structure; returns them."""

    def check(generator: Callable[..., list[np.ndarray]], n: int, seed: int) -> list[np.ndarray]:
        a = generator(np.random.default_rng(seed), n, size=96)
        b = generator(np.random.default_rng(seed), n, size=96)
        assert len(a) == n and all(np.array_equal(x, y) for x, y in zip(a, b))
        for im in a:
            assert im.shape == (96, 96) and im.dtype == np.float32 and 0.0 <= im.min() and im.max() <= 255.0
            assert im.std() > 3.0  # every kind has structure
        return a

    return check
