"""Model-independent measurement on in-memory frame sequences (fast, no bags)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from noise_monitor.bag.reader import open_bag
from noise_monitor.lab.compare import Comparison, baseline_effects
from noise_monitor.lab.measure import MIN_SPREAD_DOF, _within_cell_spread, measure_frames
from noise_monitor.lab.quantization import quantized_variance
from noise_monitor.lab.synthetic import simulate_frames
from noise_monitor.monitor.frame import Frame
from noise_monitor.physics import CameraMetadata, NoiseModel, load_profile

torch.set_num_threads(1)
PROFILE = load_profile("icx285")
SWEEP = ((6.0, 0.01, 25.0), (12.0, 0.01, 25.0))


def _pooled(meas, comp: str) -> float:
    vals = [c.values[comp] for c in meas.cells]
    return float(np.mean(vals))


def test_temporal_noise_matches_the_paper_model_on_clean_frames() -> None:
    frames = simulate_frames(PROFILE, conditions=SWEEP, frames_per_condition=6, seed=1)
    meas = measure_frames(frames)
    assert len(meas.segments) == 2 and meas.frames_used == 12
    model = NoiseModel()
    z = []
    for cell in meas.cells:
        seg = meas.segments[cell.segment]
        pred = model.predict(seg.intensity_dn[cell.block_index], seg.meta)
        expected = float(np.mean(pred["total"] ** 2)) + 1.0 / 12.0  # + 8-bit rounding
        z.append((cell.values["temporal"] - expected) / cell.errors["temporal"])
        assert abs(cell.values["fixed"]) < 5 * cell.errors["fixed"] + 0.05
    assert abs(np.mean(z)) < 1.0 and np.std(z) < 2.0
    assert meas.quant_step_dn == 1.0


def test_fixed_pattern_effects_land_in_their_components() -> None:
    frames = simulate_frames(PROFILE, effects=["prnu=2", "column_offsets=2"], conditions=SWEEP,
                             frames_per_condition=5, seed=2)
    meas = measure_frames(frames)
    # column offsets: pooled per segment, 2 DN -> 4 DN^2 (the realised 160-column pattern varies ~10 %)
    assert _pooled(meas, "column") == pytest.approx(4.0, rel=0.25)
    assert abs(_pooled(meas, "row")) < 0.3
    # PRNU: fixed white variance (0.02 v)^2 per cell
    for cell in meas.cells:
        expected = (0.02 * cell.intensity_dn) ** 2
        assert cell.values["fixed"] == pytest.approx(expected, abs=4 * cell.errors["fixed"] + 0.1 * expected)


def test_hot_pixels_are_counted_as_outliers() -> None:
    hot = "hot_pixels:fraction=0.01,dark_multiplier=10"
    frames = simulate_frames(PROFILE, effects=[hot], conditions=((6.0, 0.2, 60.0),), frames_per_condition=4, seed=3)
    meas = measure_frames(frames)
    seg = meas.segments[0]
    model = NoiseModel(baseline_effects(PROFILE, seg.meta, True))
    hot_model = Comparison(meas, model.with_effects(hot))
    (count,), (amplitude,) = hot_model.outlier_expectation()
    assert count > 50
    assert seg.outlier_pixels == pytest.approx(count, rel=0.25)
    assert seg.outlier_amplitude_dn == pytest.approx(amplitude, rel=0.15)
    base = Comparison(meas, model).residuals()
    with_hot = hot_model.residuals()
    assert np.sum(base**2) > 2.0 * base.size  # the paper model cannot explain the outliers ...
    assert np.sum(with_hot**2) < 1.2 * with_hot.size  # ... the model with the true hot pixels can


def test_quantization_step_from_the_histogram() -> None:
    frames = simulate_frames(PROFILE, effects=["quantization=6"], conditions=SWEEP, frames_per_condition=3, seed=4)
    meas = measure_frames(frames)
    assert meas.quant_step_dn == 4.0  # 255/63 = 4.05 DN on the 8-bit grid: gaps of 4 (and some 5)


def test_quantized_variance_limits() -> None:
    added, fixed, spread = quantized_variance(np.array([0.01, 5.0]), 1.0)
    assert 0.01**2 + added[0] < 0.1 / 12.0  # noise far below the step is (mostly) erased
    assert spread[0] > added[0]  # ... except where the level sits on a decision threshold
    assert added[1] == pytest.approx(1.0 / 12.0) and spread[1] < 1e-9  # dithered: LSB^2/12
    assert fixed[0] == pytest.approx(1.0 / 12.0, rel=0.1)  # undithered, phases spread: a fixed bias pattern
    assert fixed[1] < 1e-6
    added, fixed, _ = quantized_variance(np.array([0.01]), 1.0, level_dn=np.array([3.0]), span_dn=np.array([0.0]))
    assert added[0] < 1e-3 and fixed[0] < 1e-3  # one flat region on an output level: nothing varies


def _Frame(image_dn: np.ndarray | None, metadata: CameraMetadata | None, image_error: str | None = None) -> Frame:
    return Frame(0, image_dn, metadata, image_error=image_error)


def test_unusable_input_gives_clear_errors() -> None:
    meta = PROFILE.metadata(gain_db=0.0, exposure_time_s=0.01, sensor_temperature_c=25.0)
    with pytest.raises(ValueError, match="no usable frames.*no metadata for this image: 1"):
        measure_frames([_Frame(np.zeros((64, 64)), None)])
    with pytest.raises(ValueError, match="smaller than one"):
        measure_frames([_Frame(np.zeros((4, 64)), meta)])
    with pytest.raises(ValueError, match="no usable frames"):
        measure_frames([])
    flat = np.full((64, 64), 255.0)  # saturated: nothing measurable
    with pytest.raises(ValueError, match="no flat, unclipped"):
        measure_frames([_Frame(flat, meta), _Frame(flat, meta)])
    good = simulate_frames(PROFILE, conditions=SWEEP[:1], frames_per_condition=2, width=64, height=64)
    meas = measure_frames([*good, _Frame(np.zeros((32, 32)), meta), _Frame(None, meta, image_error="corrupt")])
    assert meas.skipped == {"image size changed": 1, "image unusable: corrupt": 1}


def test_short_noisy_holds_are_not_selected_on_their_own_noise() -> None:
    """A 3-frame hold at sigma 20 DN, 4 sigma above 0: the clipping test must not keep the blocks whose
    noise came out small (testing the noisy hold mean's darkest pixel against each block's own sigma read
    the temporal variance ~5 % low)."""
    meta = PROFILE.metadata(gain_db=0.0, exposure_time_s=0.01, sensor_temperature_c=25.0)
    rng = np.random.default_rng(5)
    blob = cv2.GaussianBlur(rng.standard_normal((256, 320)), (0, 0), 1.5)
    scene = 125.0 + 100.0 * blob / np.abs(blob).max()  # a texture to register the frames by ...
    scene[64:192, 80:240] = 80.0  # ... around a flat region at 80 DN
    frames = [Frame(i, np.clip(np.rint(scene + rng.normal(0.0, 20.0, scene.shape)), 0, 255), meta)
              for i in range(3)]
    meas = measure_frames(frames)
    assert len(meas.segments) == 1
    seg = meas.segments[0]
    flat = seg.intensity_dn < 100.0
    temporal = seg.values["temporal"][flat]
    assert temporal.size > 0.9 * 16 * 20  # the flat 80 DN part is not near clipping
    truth = 400.0 + 1.0 / 12.0  # + 8-bit rounding (clipping at 0, 4 sigma away, takes < 0.1 %)
    se = float(temporal.std(ddof=1)) / np.sqrt(temporal.size)  # ~0.5 %
    assert abs(float(temporal.mean()) - truth) < 3.0 * se


def test_cross_view_fixed_pattern_is_not_weighted_by_its_own_realization() -> None:
    """PRNU 3 % seen from ten 3-frame holds at gains 0-24 dB: each block's cross energies with its partner views,
    weighted, are (0.03 v_here)(0.03 v_there) on average. An exclusion taken from each block's own white variance
    (its pattern and its view's noise, which enter the cross energies too) read 1.2 % low (-6.6 standard errors
    over these three seeds); from its neighbours' (``measure._texture_white``) 0.998 over six."""
    gains = (0.0, 24.0, 6.0, 18.0, 12.0) * 2
    ratios = []
    for seed in (1, 2, 3):
        frames = simulate_frames(PROFILE, effects=["prnu=3"], conditions=tuple((g, 0.01, 25.0) for g in gains),
                                 frames_per_condition=3, width=320, height=256, seed=seed)
        for seg in measure_frames(frames).segments:
            if seg.partners:
                w = seg.partner_weight
                model = 0.03**2 * seg.intensity_dn[:, None] * seg.partner_intensity_dn
                ratios.append(np.sum(w * seg.partner_values["fixed"], axis=1) / np.sum(w * model, axis=1))
    r = np.concatenate(ratios)
    assert r.size > 15000
    assert abs(r.mean() - 1.0) < 3.0 * r.std(ddof=1) / np.sqrt(r.size)


def test_component_error_counts_a_segment_once():
    """The components table's error of the mean treats a segment's cells (which share its frames) as one
    draw: the same values repeated within 8 segments are 8 draws, not 64."""
    from noise_monitor.lab.compare import _clustered_se

    rng = np.random.default_rng(3)
    draws = rng.normal(0.0, 1.0, 8)
    repeated = np.repeat(draws, 8)
    clustered = _clustered_se(repeated, np.repeat(np.arange(8), 8).tolist())
    naive = _clustered_se(repeated, list(range(64)))
    assert clustered == pytest.approx(np.sqrt(8 / 7) * draws.std() / np.sqrt(8), rel=1e-9)
    assert naive == pytest.approx(np.sqrt(64 / 63) * draws.std() / 8, rel=1e-9)  # 64 independent cells
    assert clustered > 2.9 * naive
    assert _clustered_se(repeated, [0] * 64) == 0.0


@pytest.mark.parametrize("k", [2, 3])
def test_blinking_pixel_count_matches_its_expectation_on_clean_frames(k: int) -> None:
    """On clean frames the blinking-pixel test flags as many pixels as its expectation says (within 3.5 sigma):
    the level it compares with is the block's own median, whose scatter the bare chi-square tail leaves out (15-25 %
    too few expected at 2-3 frames, which read a clean recording of a grainy scene as blinking pixels). From 4 frames
    on a few per cent more are flagged than expected (8 % at 4, over five seeds: the photon noise's own tail and the
    intensity spread inside gradient blocks), a share the 0.1 %-of-pixels floor of the claim absorbs."""
    conditions = ((18.0, 0.01, 25.0), (21.0, 0.01, 25.0), (24.0, 0.01, 25.0))
    frames = simulate_frames(PROFILE, conditions=conditions, frames_per_condition=k, width=320, height=256, seed=40 + k)
    meas = measure_frames(frames)
    observed = sum(s.temporal_spikes for s in meas.segments)
    expected = sum(s.temporal_spikes_expected for s in meas.segments)
    assert len(meas.segments) == 3 and expected > 100
    assert abs(observed - expected) < 3.5 * np.sqrt(expected), (observed, expected)


def test_temporal_row_noise_leaves_no_block_out_of_the_temporal_noise(outside, tmp_path) -> None:
    """Row offsets of 2 DN drawn anew every frame move the block means from frame to frame as a scene change would;
    the pure-noise test left 127 blocks of a small campaign out for it (3 of its 18 cells), though the camera's own
    noise. With each frame's row and column offsets out of the test (not of the measurement), the same blocks and
    cells as the clean campaign."""
    def measured(effect):
        bag = outside.campaign_bag(tmp_path / f"{effect}.mcap", effect, frames=64, width=160, height=128, seed=3)
        with open_bag(bag) as reader:
            return measure_frames(list(reader.frames(load_profile("ev76c661"))))

    clean, rows = measured(None), measured("row_noise")
    assert sum(s.excluded.get("not_static", 0) for s in rows.segments) == 0
    assert len(rows.cells) == len(clean.cells)
    assert [s.intensity_dn.size for s in rows.segments] == pytest.approx([s.intensity_dn.size for s in clean.segments],
                                                                         abs=10)
    t_rows = np.mean([c.values["temporal_row"] for c in rows.cells])
    assert np.sqrt(t_rows) == pytest.approx(2.0, rel=0.1)  # the row noise is measured, not taken out


def test_a_cell_of_few_blocks_takes_its_segments_within_cell_spread_as_its_error_floor() -> None:
    """Six blocks that happen to agree to 0.001 DN^2 would state an error 1000 times too small: a cell's error is at
    least its segment's pooled spread about the bins' means over the square root of its blocks (sum of squares 0 + 9
    + 9 over 5 + 9 + 9 degrees of freedom); the pooled components keep their own, and fewer than MIN_SPREAD_DOF
    degrees of freedom give no floor."""
    rng = np.random.default_rng(5)
    tight = 1.0 + 0.001 * rng.standard_normal(6)
    wide = [2.0 + (z := rng.standard_normal(10)) / z.std(ddof=1), 3.0 + (z := rng.standard_normal(10)) / z.std(ddof=1)]
    fixed = np.concatenate([tight, *wide])
    bins = np.repeat([0, 1, 2], [6, 10, 10])
    spread = _within_cell_spread({"fixed": fixed, "column": fixed}, bins)
    ss = float(np.sum((tight - tight.mean()) ** 2))
    assert spread == {"fixed": pytest.approx(np.sqrt((ss + 18.0) / 23.0))}
    assert 5 + 3 < MIN_SPREAD_DOF and _within_cell_spread({"fixed": fixed[:10]}, bins[:10]) == {}
