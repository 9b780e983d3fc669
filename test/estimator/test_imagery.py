"""More varied training imagery (issue 15): man-made procedural scenes, photographs at 1x and arbitrary
rotations, JPEG-compressed sources; the native-resolution held-out photos; old and new weights side by side."""
from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

from noise_monitor.cli import main as cli_main
from noise_monitor.estimator.data import generate, imagery_of
from noise_monitor.estimator.evaluate import HELDOUT_SETS
from noise_monitor.estimator.images import (
    SKIMAGE_PHOTOS,
    Imagery,
    diverse_photo_variants,
    inscribed_size,
    jpeg_compress,
    matplotlib_photos,
    pywavelets_photos,
    rotate_inscribed,
    skimage_originals,
    source_images,
)
from noise_monitor.estimator.inference import WEIGHTS_DIR
from noise_monitor.estimator.procedural import (
    MANMADE_KINDS,
    bars,
    chart_images,
    grain_images,
    manmade_images,
    plain_grating_images,
    polygon_leaves,
)
from noise_monitor.estimator.residuals import immerkaer

VARIED = Imagery(photo_scales=(1.0, 4.0), photo_native=0.5, photo_rotate=0.5, jpeg=0.5, manmade=2, grain=1, charts=1, gratings=1)


def test_manmade_images_are_seeded_on_the_dn_scale_with_flat_faces_and_straight_edges(seeded_images) -> None:
    a = seeded_images(manmade_images, 2 * len(MANMADE_KINDS), 7)
    for im in a:
        # flat faces: most of the image has almost no pixel-scale residual (a shading ramp leaves none) ...
        resid = np.abs(immerkaer(im[None])[0])
        assert np.median(resid) < 0.5
        # ... and edges: some pixels have a large one (3 DN for the faintest bars)
        assert resid.max() > 1.0


def test_grain_is_pixel_scale_content_correlated_unlike_white_noise(seeded_images) -> None:
    white = np.random.default_rng(0).normal(100.0, 3.0, (96, 96))
    for im in [white, *seeded_images(grain_images, 6, 5)]:
        r = immerkaer(im[None].astype(np.float64))[0]
        lag1 = np.corrcoef(r[:, :-1].ravel(), r[:, 1:].ravel())[0, 1]
        if im is white:
            assert lag1 < -0.64  # the Laplacian of white noise
        else:  # grain of 0.5-8 DN at 0.4-1.5 px: pixel-scale content, correlated beyond one pixel
            assert r.std() > 0.3 and -0.62 < lag1 < -0.3


def test_charts_span_the_intensity_range_in_flat_tiles_with_edges(seeded_images) -> None:
    for im in seeded_images(chart_images, 4, 11):
        # the levels of a step wedge over the whole range, the clipped ends included ...
        assert np.percentile(im, 2) < 25.0 and np.percentile(im, 98) > 230.0
        # ... in tiles: most pixels have little pixel-scale residual, the tile edges a large step
        assert np.median(np.abs(immerkaer(im[None])[0])) < 1.0 and np.abs(np.diff(im, axis=1)).max() > 10.0


def test_plain_gratings_are_line_spectra_over_the_whole_image(seeded_images) -> None:
    for im in seeded_images(plain_grating_images, 6, 13):
        f = np.abs(np.fft.rfft2(im - im.mean())) ** 2
        f[0, 0] = 0.0
        fine = np.hypot(*np.meshgrid(np.fft.fftfreq(96), np.fft.rfftfreq(96), indexing="ij")) >= 1 / 6.5
        # a 1.5-6 px grating puts its power in a few fine-frequency bins (Hann-free: some leakage)
        assert np.sort(f[fine])[-8:].sum() > 0.3 * f.sum()


def test_manmade_kinds_alternate():
    ims = manmade_images(np.random.default_rng(3), 2, size=128)
    rng = np.random.default_rng(3)
    first = np.clip(polygon_leaves(rng, 128), 0, 255).astype(np.float32)
    second = np.clip(bars(rng, 128), 0, 255).astype(np.float32)
    assert np.array_equal(ims[0], first) and np.array_equal(ims[1], second)


def test_inscribed_rectangle_and_rotation_without_border():
    assert inscribed_size(100, 60, 0.0) == (98, 58)
    w, h = inscribed_size(200, 200, math.radians(45.0))
    assert abs(w - 200 / math.sqrt(2)) <= 3 and abs(h - 200 / math.sqrt(2)) <= 3
    flat = np.full((80, 120), 77.0, np.float32)
    rot = rotate_inscribed(flat, 33.0)
    assert rot.shape == inscribed_size(120, 80, math.radians(33.0))[::-1]
    assert np.allclose(rot, 77.0, atol=1e-3)  # no border fill inside the crop


def test_jpeg_round_trip_keeps_the_scene_and_adds_blocking():
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:64, 0:64]
    img = (100.0 + 0.8 * xx + 30.0 * (yy > 30) + rng.normal(0, 3.0, (64, 64))).astype(np.float32)
    low, high = jpeg_compress(img, 40), jpeg_compress(img, 95)
    assert low.dtype == np.float32 and low.shape == img.shape and 0 <= low.min() and low.max() <= 255
    assert np.abs(high - img).mean() < np.abs(low - img).mean() < 6.0
    # quality 40 removes much of the fine noise (it becomes blocks): the pixel-scale residual falls
    assert np.std(immerkaer(low[None])) < 0.8 * np.std(immerkaer(img[None]))


def test_diverse_photo_variants_native_rotated_and_reproducible():
    originals = skimage_originals()
    a = diverse_photo_variants(np.random.default_rng(5), 3, VARIED)
    b = diverse_photo_variants(np.random.default_rng(5), 3, VARIED)
    assert len(a) == 3 * len(SKIMAGE_PHOTOS) and all(np.array_equal(x, y) for x, y in zip(a, b))
    assert all(0.0 <= im.min() and im.max() <= 255.0 and im.dtype == np.float32 for im in a)
    shapes = [(im.shape, originals[i // 3].shape) for i, im in enumerate(a)]
    assert any(s == o for s, o in shapes)  # some at native resolution, unrotated
    assert any(s[0] < o[0] / 1.5 for s, o in shapes)  # some downscaled
    # rotated ones are cropped inside: not a 90-degree multiple's shape
    assert any(s != o and s[::-1] != o and s[0] > o[0] / 1.5 for s, o in shapes)


def test_imagery_defaults_leave_datasets_bit_identical_and_options_are_recorded():
    plain = generate(8, 32, seed=3, progress=False, photo_variants=1)
    same = generate(8, 32, seed=3, progress=False, photo_variants=1, imagery=Imagery())
    assert np.array_equal(plain["noisy"], same["noisy"]) and imagery_of(plain) == Imagery()
    assert imagery_of({}) == Imagery()
    varied = generate(8, 32, seed=3, progress=False, photo_variants=1, imagery=VARIED)
    assert imagery_of(varied) == VARIED and not np.array_equal(varied["noisy"], plain["noisy"])
    imgs = source_images("train", np.random.default_rng(2), n_dead_leaves=1, variants=1, imagery=VARIED)
    assert len(imgs) == len(SKIMAGE_PHOTOS) + 1 + VARIED.manmade + VARIED.grain + VARIED.charts + VARIED.gratings
    with pytest.raises(ValueError, match="train split"):
        source_images("photos", np.random.default_rng(0), imagery=Imagery(manmade=1))
    with pytest.raises(ValueError, match="photo variants"):
        source_images("train", np.random.default_rng(0), imagery=Imagery(photo_rotate=0.5))
    with pytest.raises(ValueError, match="probability"):
        Imagery(jpeg=1.5)
    with pytest.raises(ValueError, match="scales"):
        Imagery(photo_scales=(0.5, 2.0))


def test_train_cli_imagery_options(tmp_path, capsys):
    args = ["train", "--variant", "full_meta", "--out", str(tmp_path), "--steps", "1", "--batch", "2",
            "--patches", "8", "--patch-size", "32", "--threads", "1", "--photo-variants", "1"]
    extra = ["--photo-scales", "1", "4", "--photo-native", "0.3", "--photo-rotate", "0.5", "--jpeg", "0.25",
             "--manmade", "2", "--grain", "1", "--charts", "1", "--gratings", "1", "--keep-checkpoints", "--checkpoint-every", "1"]
    assert cli_main(args + extra) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["imagery"] == {"photo_scales": [1.0, 4.0], "photo_native": 0.3, "photo_rotate": 0.5, "jpeg": 0.25,
                                  "manmade": 2, "grain": 1, "charts": 1, "gratings": 1}
    assert "--photo-scales 1 4 " in summary["command"] and (tmp_path / "step_1.pt").is_file()
    assert cli_main(args) == 2 and "imagery options" in capsys.readouterr().err  # the dataset is another one
    rc = cli_main(["train", "--variant", "full_meta", "--out", str(tmp_path / "x"), "--photo-rotate", "0.5"])
    assert rc == 2 and "--photo-variants" in capsys.readouterr().err


def test_native_heldout_photos_and_distinct_seeds():
    assert HELDOUT_SETS["photos_native"].split == "photos_native"
    native = matplotlib_photos(native=True) + pywavelets_photos(native=True)
    half = matplotlib_photos() + pywavelets_photos()
    assert len(native) == len(half) and any(n.shape[0] >= 2 * h.shape[0] - 1 for n, h in zip(native, half))
    imgs = source_images("photos_native", np.random.default_rng(0))
    assert [im.shape for im in imgs] == [im.shape for im in native]
    seeds = [s for hs in HELDOUT_SETS.values() for s in hs.seeds.values()]
    assert len(seeds) == len(set(seeds))


def test_evaluate_compare_weights_side_by_side(tmp_path, capsys):
    weights = tmp_path / "w"
    weights.mkdir()
    shutil.copy(WEIGHTS_DIR / "full_meta.pt", weights / "full_meta.pt")
    rc = cli_main(["evaluate", "--weights-dir", str(weights), "--variants", "full_meta", "--patches", "10",
                   "--parts", "a", "--patch-size", "32", "--no-peers", "--no-sweep", "--heldout", "photos_native",
                   "--compare", f"full_meta_old={WEIGHTS_DIR / 'full_meta.pt'}",
                   "--cache", str(tmp_path / "cache"), "--json", str(tmp_path / "e.json"), "--device", "cpu"])
    assert rc == 0
    r = json.loads((tmp_path / "e.json").read_text())
    assert r["heldout"] == "photos_native"
    rows = r["parts"]["a"]
    assert rows["full_meta"]["xi"] == rows["full_meta_old"]["xi"]  # the same weights on the same data
    assert rows["full_meta_old"]["minus_full_meta"]["xi_rms"] == [0.0, 0.0, 0.0]  # paired: nothing differs
    bad = cli_main(["evaluate", "--weights-dir", str(weights), "--variants", "full_meta", "--compare", "full_meta=x.pt"])
    assert bad == 2 and "already used" in capsys.readouterr().err


def test_model_card_describes_the_varied_imagery():
    from noise_monitor.estimator.card import _procedural, _variants

    plain = {"photo_variants": 3, "procedural": 40}
    assert "1.5-4x downscale" in _variants(plain) and "man-made" not in _procedural(plain)
    varied = {"photo_variants": 4, "procedural": 0, "imagery": VARIED.as_dict()}
    assert "50% rotated" in _variants(varied) and "50% at native resolution" in _variants(varied)
    assert "2 man-made procedural scenes" in _procedural(varied) and "50% of the source images JPEG" in _procedural(varied)
