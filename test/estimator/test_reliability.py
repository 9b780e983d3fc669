"""Bad-input matrix of the estimator: weights missing or corrupt, CUDA requested but absent, bad patches
and metadata; valid but extreme inputs give finite numbers.

Expected: FileNotFoundError / ValueError naming the file or the problem (the CLI prints it on one line
and exits 2), never an unpickling traceback or a NaN.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.cli import main
from noise_monitor.estimator import load
from noise_monitor.estimator.inference import WEIGHTS_DIR
from noise_monitor.physics import CameraMetadata, load_profile
from noise_monitor.physics.metadata import NUMERIC_FIELDS, VALID_RANGES

torch.set_num_threads(1)
BUNDLED = WEIGHTS_DIR / "full_meta.pt"
PROFILE = load_profile("icx285")
META = PROFILE.metadata(gain_db=12.0, exposure_time_s=0.01, sensor_temperature_c=30.0)
WITHOUT_CUDA = pytest.mark.skipif(torch.cuda.is_available(), reason="checks the behaviour without CUDA")


@pytest.fixture(scope="module")
def estimator():
    return load("full_meta", device="cpu")


def _checkpoint() -> dict:
    return torch.load(BUNDLED, map_location="cpu", weights_only=False)


def _corrupt(kind: str, path: Path) -> Path:
    """Write a broken weights file of the given kind."""
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "text":
        path.write_text("these are not weights\n" * 10)
    elif kind == "truncated":
        path.write_bytes(BUNDLED.read_bytes()[: BUNDLED.stat().st_size // 2])
    elif kind == "tensor":
        torch.save(torch.zeros(3), path)
    elif kind == "foreign dict":
        torch.save({"epoch": 3, "model": {}}, path)
    elif kind == "no config":
        ck = _checkpoint()
        del ck["config"]
        torch.save(ck, path)
    elif kind == "wrong layer shapes":
        ck = _checkpoint()
        key = next(k for k, v in ck["state_dict"].items() if v.ndim >= 2)
        ck["state_dict"][key] = torch.zeros(tuple(s + 1 for s in ck["state_dict"][key].shape))
        torch.save(ck, path)
    elif kind == "missing layer":
        ck = _checkpoint()
        ck["state_dict"].pop(next(iter(ck["state_dict"])))
        torch.save(ck, path)
    return path


CORRUPT = {
    "empty": "weights file .*empty.pt is not a readable checkpoint \\(EOFError",
    "text": "weights file .*text.pt is not a readable checkpoint \\(",  # weights_only unpickler: any error type
    "truncated": "weights file .*truncated.pt is not a readable checkpoint",
    "tensor": ".*tensor.pt is not an estimator checkpoint",
    "foreign dict": ".*foreign dict.pt is not an estimator checkpoint",
    "no config": ".*no config.pt is a damaged full_meta checkpoint \\(KeyError: 'config'\\)",
    "wrong layer shapes": ".*wrong layer shapes.pt is a damaged full_meta checkpoint \\(RuntimeError: .*size mismatch",
    "missing layer": ".*missing layer.pt is a damaged full_meta checkpoint \\(RuntimeError: .*Missing key",
}


@pytest.mark.parametrize("kind", sorted(CORRUPT))
def test_corrupt_weights_are_a_value_error_naming_the_file(tmp_path, kind):
    path = _corrupt(kind, tmp_path / f"{kind}.pt")
    with pytest.raises(ValueError, match=CORRUPT[kind]):
        load("full_meta", device="cpu", weights=path)


def test_missing_weights(tmp_path):
    with pytest.raises(FileNotFoundError, match="weights file .*nowhere.pt not found"):
        load("full_meta", device="cpu", weights=tmp_path / "nowhere.pt")
    with pytest.raises(FileNotFoundError, match="weights file .* not found"):
        load("full_meta", device="cpu", weights=tmp_path)  # a folder is not a weights file
    with pytest.raises(ValueError, match="unknown estimator 'full_meat'; choose from"):
        load("full_meat", device="cpu")


@WITHOUT_CUDA
@pytest.mark.parametrize("device", ["cuda", "cuda:0", "cuda:1"])
def test_cuda_requested_but_absent(device):
    with pytest.raises(ValueError, match=f"device '{device}' requested but CUDA is not available .*use --device cpu"):
        load("full_meta", device=device)


@WITHOUT_CUDA
def test_auto_device_falls_back_to_cpu_and_unknown_devices_are_named():
    assert str(load("full_meta", device="auto").device) == "cpu"
    with pytest.raises(ValueError, match="device must be one of \\('auto', 'cpu', 'cuda'\\).*got 'gpu'"):
        load("full_meta", device="gpu")


# --- the CLI prints these on one line and exits 2 --------------------------------------------------
@pytest.fixture(scope="module")
def bag(tmp_path_factory, estimator) -> Path:
    ps = estimator.patch_size
    return simulate_bag(tmp_path_factory.mktemp("est") / "b.mcap", "icx285", "static", frames=2, width=ps,
                        height=ps, hold_s=0.0)


def _cli(capsys, *args: str) -> tuple[int, str]:
    code = main([str(a) for a in args])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip() and "%|" not in ln]
    assert "Traceback" not in err and len(lines) == 1, err
    return code, lines[0]


@WITHOUT_CUDA
def test_replay_cli_with_bad_weights_or_device(capsys, tmp_path, bag):
    out = ["--out", tmp_path / "o", "--no-plot"]
    code, line = _cli(capsys, "replay", bag, "--profile", "icx285", "--weights", _corrupt("text", tmp_path / "w.pt"), *out)
    assert code == 2 and line.startswith("noise-monitor replay: error: weights file") and "w.pt" in line
    code, line = _cli(capsys, "replay", bag, "--profile", "icx285", "--weights", tmp_path / "none.pt", *out)
    assert code == 2 and "none.pt not found" in line
    code, line = _cli(capsys, "replay", bag, "--profile", "icx285", "--device", "cuda", *out)
    assert code == 2 and "CUDA is not available" in line


@WITHOUT_CUDA
@pytest.mark.parametrize("args,needle", [
    (["--device", "cuda"], "CUDA is not available"),
    (["--weights", "{tmp}/none.pt"], "none.pt not found"),
    (["--weights", "{tmp}/w.pt"], "is not a readable checkpoint"),
])
def test_node_cli_with_bad_weights_or_device_exits_2(capsys, tmp_path, args, needle):
    _corrupt("truncated", tmp_path / "w.pt")
    code, line = _cli(capsys, "node", "--duration", "5", *[a.format(tmp=tmp_path) for a in args])
    assert code == 2 and line.startswith("noise-monitor node: error: ") and needle in line


# --- inputs to predict ---------------------------------------------------------------------------
@pytest.mark.parametrize("patches,match", [
    (np.full((2, 64, 64), np.nan, np.float32), "NaN or inf"),
    (np.full((1, 64, 64), np.inf, np.float32), "NaN or inf"),
    (np.full((1, 64, 64), -3.0, np.float32), "0..255 DN scale"),
    (np.full((1, 64, 64), 4095.0, np.float32), "0..255 DN scale.*scale higher bit depths"),
    (np.zeros((0, 64, 64), np.float32), "N >= 1"),
    (np.zeros((64,), np.float32), "shape \\(N, H, W\\)"),
    (np.zeros((1, 8, 8), np.float32), "at least 16x16"),
    (np.zeros((1, 64, 64), np.complex64), "real numbers"),
])
def test_bad_patches_are_value_errors(estimator, patches, match):
    with pytest.raises(ValueError, match=match):
        estimator.predict(patches, META)


def test_bad_metadata_arguments_are_value_errors(estimator):
    patches = np.full((2, 64, 64), 100.0, np.float32)
    with pytest.raises(ValueError, match="got 1 metadata for 2 patches"):
        estimator.predict(patches, [META])
    with pytest.raises(ValueError, match="metas\\[1\\] is dict, not CameraMetadata"):
        estimator.predict(patches, [META, META.as_dict()])
    with pytest.raises(ValueError, match="metas must be a CameraMetadata"):
        estimator.predict(patches, "icx285")


def _extreme_metas() -> list[CameraMetadata]:
    lo = {n: VALID_RANGES[n][0] for n in NUMERIC_FIELDS}
    hi = {n: VALID_RANGES[n][1] for n in NUMERIC_FIELDS}
    return [CameraMetadata(**lo, sensor_type="cmos"), CameraMetadata(**hi, sensor_type="ccd"),
            PROFILE.metadata(gain_db=48.0, exposure_time_s=600.0, sensor_temperature_c=150.0),
            PROFILE.metadata(gain_db=0.0, exposure_time_s=1e-7, sensor_temperature_c=-80.0)]


def test_extreme_but_valid_inputs_give_finite_non_negative_sigmas(estimator, rng):
    """Black, saturated, flat and pure-noise patches at the edges of the valid metadata ranges."""
    patches = np.stack([np.zeros((64, 64)), np.full((64, 64), 255.0), np.full((64, 64), 128.0),
                        rng.uniform(0, 255, (64, 64)), np.clip(rng.normal(128, 40, (64, 64)), 0, 255)]).astype(np.float32)
    for meta in _extreme_metas():
        out = estimator.predict(patches, meta)
        for key in ("pn", "dcsn", "rn", "total", "sigma_image", "xi"):
            assert out[key].shape == (5,) and np.all(np.isfinite(out[key])), (key, meta)
        for key in ("pn", "dcsn", "rn", "total", "sigma_image"):
            assert np.all(out[key] >= 0.0), (key, meta)
        np.testing.assert_allclose(out["xi"], out["total"] - out["sigma_image"], rtol=1e-9, atol=1e-9)
