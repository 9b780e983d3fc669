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


@pytest.fixture
def widened_reads_as_before() -> Callable[..., None]:
    """Check ``train.with_new_inputs``: full_meta weights ``ck`` widened to the configuration ``cfg`` (``extra`` new
    scalar inputs at MLP input column ``at``) read ``noisy`` at ``meta`` as before, under torch and ONNX Runtime,
    and the estimator tells the new inputs (``flags``: its ``_extra_scalars``)."""
    import torch

    from noise_monitor.estimator.inference import FullMetaEstimator
    from noise_monitor.estimator.networks import ImageNoiseNet
    from noise_monitor.estimator.train import with_new_inputs

    def check(ck: dict, cfg, at: int, extra: int, noisy: np.ndarray, meta, flags: tuple[bool, bool]) -> None:
        cpu = torch.device("cpu")
        wide = ImageNoiseNet(cfg)
        wide.load_state_dict(with_new_inputs(ck["state_dict"], at, extra))
        widened = {**ck, "config": cfg.as_dict(), "state_dict": wide.state_dict()}
        ref = FullMetaEstimator(ck, cpu, backend="torch").predict(noisy, meta)
        for backend in ("torch", "onnx"):
            est = FullMetaEstimator(widened, cpu, backend=backend)
            assert est._extra_scalars == flags
            out = est.predict(noisy, meta)
            for key in ("sigma_image", "sigma_image_error"):
                assert out[key] == pytest.approx(ref[key], rel=1e-4), (backend, key)

    return check
