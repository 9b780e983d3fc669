"""Texture evidence (white noise reads zero at any level) and the procedural training images."""
from __future__ import annotations

import numpy as np
import pytest

from noise_monitor.estimator.evidence import N_EVIDENCE, texture_evidence
from noise_monitor.estimator.procedural import KINDS, procedural_images


def _grating(period: float, amp: float, angle: float, size: int = 64) -> np.ndarray:
    yy, xx = np.mgrid[0:size, 0:size]
    return (100.0 + amp * np.sin(2 * np.pi * (np.cos(angle) * xx + np.sin(angle) * yy) / period)).astype(np.float32)


def test_white_noise_reads_zero_at_any_level_and_shape():
    rng = np.random.default_rng(0)
    noise = rng.standard_normal((64, 64, 64)).astype(np.float32)
    ramp = np.linspace(20.0, 220.0, 64, dtype=np.float32)[None, None, :].repeat(64, axis=1)
    shape = np.sqrt(ramp / ramp.mean())  # photon noise: sigma grows with the intensity
    for level in (0.5, 3.0, 12.0):
        ev = texture_evidence(np.clip(ramp + level * shape * noise, 0, 255), np.broadcast_to(shape, noise.shape))
        assert ev.shape == (64, N_EVIDENCE) and ev.dtype == np.float32
        assert np.all(np.abs(ev.mean(axis=0)) < 0.05), (level, ev.mean(axis=0))


def test_pixel_scale_texture_departs_from_white_noise():
    rng = np.random.default_rng(1)
    noisy = np.stack([_grating(p, 20.0, a) + 2.0 * rng.standard_normal((64, 64)).astype(np.float32)
                      for p, a in [(2.2, 0.3), (3.0, 1.1), (4.0, 2.0), (5.5, 0.7)]])
    ev = texture_evidence(noisy)
    white = texture_evidence(100.0 + 2.0 * rng.standard_normal((32, 64, 64)).astype(np.float32))
    z = np.abs(ev - white.mean(axis=0)) / white.std(axis=0)  # in units of white noise's spread
    assert np.all(z.max(axis=1) > 20.0)  # every grating: far outside white noise on some statistic
    assert np.all(z[:3, 0] > 20.0)  # periods < 4 px: the high band's flatness alone


def test_texture_evidence_rejects_bad_input():
    with pytest.raises(ValueError, match="at least"):
        texture_evidence(np.zeros((2, 8, 8), np.float32))
    with pytest.raises(ValueError, match=r"\(N, H, W\)"):
        texture_evidence(np.zeros((64, 64), np.float32))


def test_procedural_images_are_seeded_and_on_the_dn_scale(seeded_images) -> None:
    a = seeded_images(procedural_images, 2 * len(KINDS), 5)
    # each kind has content at the noise's scale: its fine-scale power departs from white noise
    assert np.all(texture_evidence(np.stack([im[:64, :64] for im in a]))[:, 0] > 0.1)


def test_procedural_training_images_only_for_the_train_split(tmp_path, capsys):
    """``--procedural N`` adds N procedural images to the training images (recorded in the dataset); the
    held-out splits never get them; a dataset file cannot silently serve another --procedural."""
    import json

    from noise_monitor.cli import main as cli_main
    from noise_monitor.estimator.data import generate, procedural_of
    from noise_monitor.estimator.images import SKIMAGE_PHOTOS, source_images

    imgs = source_images("train", np.random.default_rng(2), n_dead_leaves=0, procedural=3)
    assert len(imgs) == len(SKIMAGE_PHOTOS) + 3
    with pytest.raises(ValueError, match="train split"):
        source_images("photos", np.random.default_rng(0), procedural=1)
    assert procedural_of(generate(8, 32, seed=3, progress=False, procedural=2)) == 2 and procedural_of({}) == 0
    args = ["train", "--variant", "full_meta", "--out", str(tmp_path), "--steps", "1", "--batch", "2",
            "--patches", "8", "--patch-size", "32", "--threads", "1"]
    assert cli_main(args + ["--procedural", "2"]) == 0
    assert json.loads(capsys.readouterr().out)["procedural"] == 2
    assert cli_main(args) == 2 and "--procedural 2" in capsys.readouterr().err
