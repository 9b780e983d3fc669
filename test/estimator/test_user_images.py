"""`noise-monitor evaluate --images`: a user's own clean images as a held-out set, scored per image."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from noise_monitor.cli import main as cli_main
from noise_monitor.estimator.user_images import load_image_set, own_noise_floor, to_scene_dn


def _smooth(h: int = 300, w: int = 320) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w]
    return (120 + 90 * np.sin(x / 40.0) * np.cos(y / 55.0)).astype(np.float32)


def _write_scenes(folder: Path, grain_dn: float = 8.0) -> None:
    """A smooth scene, and the same scene with white noise of its own (``grain_dn`` at full resolution: half of
    it after the 2x area downsampling)."""
    folder.mkdir()
    smooth = _smooth()
    grainy = smooth + np.random.default_rng(1).normal(0.0, grain_dn, smooth.shape)
    cv2.imwrite(str(folder / "smooth.png"), np.clip(np.round(smooth), 0, 255).astype(np.uint8))
    cv2.imwrite(str(folder / "grainy.png"), np.clip(np.round(grainy), 0, 255).astype(np.uint8))


def test_images_are_read_as_grayscale_dn_and_downsampled(tmp_path):
    """8-bit PNG, 16-bit TIFF (a 12-bit scene with a hot pixel: read at 12 bits), colour JPEG (RGB luma, not BGR)
    and .npy; sorted by name, halved by the default 2x area downsampling."""
    d = tmp_path / "imgs"
    d.mkdir()
    gray = np.tile(np.linspace(10, 240, 160, dtype=np.float32), (200, 1))
    cv2.imwrite(str(d / "a_gray.png"), gray.astype(np.uint8))
    deep = (gray.astype(np.uint8).astype(np.uint16) * 16)  # 12-bit values in 16-bit words
    deep[7, 9] = 65535  # a hot pixel
    cv2.imwrite(str(d / "b_deep.tif"), deep)
    red = np.zeros((200, 160, 3), np.uint8)
    red[..., 2] = 255  # OpenCV writes BGR: pure red
    cv2.imwrite(str(d / "c_red.jpg"), red, [cv2.IMWRITE_JPEG_QUALITY, 100])
    np.save(d / "d_array.npy", gray.astype(np.uint8))
    (d / "notes.txt").write_text("not an image")
    s = load_image_set([d])
    assert s.names == ("a_gray.png", "b_deep.tif", "c_red.jpg", "d_array.npy")
    assert all(im.shape == (100, 80) and im.dtype == np.float32 for im in s.images)
    assert abs(float(np.median(s.images[2])) - 0.299 * 255) < 2.0  # luma of red; BGR read as RGB would give 29
    # the 12-bit scene as bright as the 8-bit one (x 16 x 255 / 4095); until 2026-12-04 stretched between its minimum
    # and the hot pixel: the whole scene in 0..15 DN
    assert np.median(np.abs(s.images[1] - s.images[0] * np.float32(16 * 255 / 4095))) < 0.01
    assert np.allclose(s.images[0], s.images[3])
    native = load_image_set([d / "a_gray.png"], downsample=1)
    assert native.images[0].shape == (200, 160) and native.key != load_image_set([d / "a_gray.png"]).key


def test_scene_dn_keeps_the_recorded_brightness_and_refuses_what_is_no_scene():
    """Floats in [0, 1] x 255, in [0, 255] as they are (a constant 0.5 read 0 DN until 2026-12-04); 16-bit words with
    10-bit values at 10 bits; signed values below 0, black and saturated images refused."""
    rng = np.random.default_rng(3)
    scene = rng.uniform(40.0, 200.0, (64, 64)).astype(np.float32)
    assert np.allclose(to_scene_dn(scene / 255.0, "f01"), scene, atol=1e-3)
    assert np.allclose(to_scene_dn(scene.astype(np.float64), "f255"), scene, atol=1e-3)
    assert np.allclose(to_scene_dn(np.full((64, 64), 0.5), "half"), 127.5)
    ten = np.rint(scene * 4).astype(np.uint16)  # 10-bit values
    assert np.allclose(to_scene_dn(ten, "ten"), ten * np.float32(255 / 1023), atol=1e-3)
    assert np.array_equal(to_scene_dn(scene.astype(np.uint8), "u8"), scene.astype(np.uint8).astype(np.float32))
    with pytest.raises(ValueError, match="neg.npy holds negative values"):
        to_scene_dn(np.full((64, 64), -3, np.int16), "neg.npy")
    for name, img in (("black.png", np.zeros((64, 64), np.uint8)), ("sat.png", np.full((64, 64), 255, np.uint8))):
        with pytest.raises(ValueError, match=f"{name} has 100% of its pixels at 0 or 255 DN"):
            to_scene_dn(img, name)


def test_bad_images_get_clear_errors(tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "broken.png").write_bytes(b"not a png at all")
    np.save(tmp_path / "nan.npy", np.full((200, 200), np.nan))
    np.save(tmp_path / "cube.npy", np.zeros((4, 200, 200)))
    np.save(tmp_path / "two.npy", np.zeros((200, 200, 2)))
    cv2.imwrite(str(tmp_path / "small.png"), np.full((100, 300), 100, np.uint8))
    cv2.imwrite(str(tmp_path / "ok.png"), np.full((200, 200), 100, np.uint8))
    with pytest.raises(FileNotFoundError, match="not found"):
        load_image_set([tmp_path / "missing.png"])
    with pytest.raises(ValueError, match="no image"):
        load_image_set([tmp_path / "empty"])
    with pytest.raises(ValueError, match="could not be read"):
        load_image_set([tmp_path / "broken.png"])
    with pytest.raises(ValueError, match="non-finite"):
        load_image_set([tmp_path / "nan.npy"])
    for name in ("cube.npy", "two.npy"):
        with pytest.raises(ValueError, match="grayscale or colour"):
            load_image_set([tmp_path / name])
    with pytest.raises(ValueError, match="smaller than the 64 px it needs on its shorter side"):
        load_image_set([tmp_path / "small.png"])
    with pytest.raises(ValueError, match="1-4"):
        load_image_set([tmp_path / "ok.png"], downsample=5)
    with pytest.raises(ValueError, match="share a file name"):
        (tmp_path / "other").mkdir()
        cv2.imwrite(str(tmp_path / "other" / "ok.png"), np.full((200, 200), 100, np.uint8))
        load_image_set([tmp_path / "ok.png", tmp_path / "other"])


@pytest.mark.parametrize("sigma", [2.0, 4.0, 8.0])
def test_own_noise_floor_reads_an_images_own_white_noise(sigma):
    smooth = _smooth()
    noisy = smooth + np.random.default_rng(int(sigma)).normal(0.0, sigma, smooth.shape).astype(np.float32)
    assert own_noise_floor(smooth) < 0.3
    assert abs(own_noise_floor(noisy) - sigma) < 0.1 * sigma


def test_evaluate_scores_each_own_image_with_its_floor(tmp_path, capsys):
    """End to end through the CLI: the parts drawn from the user's images, every patch counted per image; the
    smooth scene is read within issue 15's per-patch limits, the scene with its own 4 DN of white noise is read
    noisier than the truth (xi low) and its floor says why. A second run reuses the cached data bit-exact."""
    _write_scenes(tmp_path / "scenes")
    args = ["evaluate", "--images", str(tmp_path / "scenes"), "--variants", "full_meta", "--patches", "80",
            "--parts", "a", "c", "--no-peers", "--cache", str(tmp_path / "cache"), "--device", "cpu"]
    assert cli_main(args + ["--json", str(tmp_path / "e.json")]) == 0
    r = json.loads((tmp_path / "e.json").read_text())
    assert r["heldout"] == "images" and [i["name"] for i in r["images"]] == ["grainy.png", "smooth.png"]
    floors = {i["name"]: i["own_noise_floor_dn"] for i in r["images"]}
    assert floors["smooth.png"] < 0.3 and abs(floors["grainy.png"] - 4.0) < 0.4
    for part in "ac":
        rows = {r["images"][row["image"]]["name"]: row for row in r["parts"][part]["full_meta"]["per_image"]}
        assert sum(row["patches"] for row in rows.values()) == 80
        smooth, grainy = rows["smooth.png"], rows["grainy.png"]
        if part == "a":
            assert smooth["xi_rms_accepted"] < 0.35 and smooth["false_alarm_rate_decided"] <= 0.02
            assert grainy["xi_mean_error"] < -1.0  # its own noise read as the camera's
        else:
            assert smooth["hit_rate_decided"] >= 0.97 and smooth["hit_rate_accepted"] <= smooth["hit_rate_decided"]
    assert cli_main(args + ["--json", str(tmp_path / "again.json"), "--plot", str(tmp_path / "p.png")]) == 0
    assert json.loads((tmp_path / "again.json").read_text())["parts"] == r["parts"]
    # a cached part cut short (a run interrupted while writing it, before writes became atomic): until 2026-12-04 a
    # BadZipFile traceback on every later run; now made again, said, with the same figures
    cached = sorted((tmp_path / "cache").glob("images-*_a_*.npz"))[0]
    cached.write_bytes(cached.read_bytes()[:100])
    capsys.readouterr()
    assert cli_main(args + ["--json", str(tmp_path / "third.json")]) == 0
    err = capsys.readouterr().err
    assert f"note: dataset {cached} cannot be read" in err and "generating it again" in err
    assert json.loads((tmp_path / "third.json").read_text())["parts"] == r["parts"]
    png = cv2.imread(str(tmp_path / "p.png"))
    assert png is not None and png.shape[0] > 300 and png.shape[1] > 400  # two parts x two images
    assert cli_main(["evaluate", "--plot", str(tmp_path / "q.png"), "--no-peers"]) == 2
    assert "give --images" in capsys.readouterr().err
    assert cli_main(args + ["--cards"]) == 2 and "leave out --images" in capsys.readouterr().err
    assert cli_main(args[:2] + [str(tmp_path / "nowhere")] + args[3:]) == 2
    assert "not found" in capsys.readouterr().err


def test_per_image_rows_cover_every_image_and_both_alarm_rules():
    """One row per image, one that drew no patch included; the accepted and decided rules differ where a declined
    patch's decision is clear."""
    from noise_monitor.estimator.evaluate import per_image

    xi = np.array([0.0, 2.0, -3.0, 0.1])
    pred = {"xi": xi, "measurable": np.array([True, True, False, True]), "sigma_image": np.array([3.0, 3.0, 6.0, 3.0]),
            "sigma_image_error": np.array([0.1, 0.1, 0.5, 0.1]), "xi_lower": np.full(4, -np.inf)}
    data = {"truth_xi": np.zeros(4), "source_index": np.array([0, 0, 2, 2])}
    rows = per_image(pred, data, "a", n_images=3)
    assert [r["image"] for r in rows] == [0, 1, 2] and rows[1] == {"image": 1, "patches": 0}
    assert rows[0]["false_alarm_rate_accepted"] == rows[0]["false_alarm_rate_decided"] == 0.5
    assert rows[2]["false_alarm_rate_accepted"] == 0.0 and rows[2]["false_alarm_rate_decided"] == 0.5
    assert rows[2]["coverage"] == 0.5 and rows[2]["xi_rms_accepted"] == 0.1
