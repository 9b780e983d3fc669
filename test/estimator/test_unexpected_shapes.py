"""Unexpected noise whose shape the stated model lacks (``Scheme.unexpected_shapes``, ``train --unexpected-shapes``)."""
from __future__ import annotations

import json

import numpy as np

from noise_monitor.cli import main as cli_main
from noise_monitor.estimator.data import Scheme, generate, scheme_of


def _bright_to_dark_variance(data: dict) -> float:
    """Median over patches of the residual variance in the brightest quarter over that in the darkest quarter."""
    ratios = []
    for clean, noisy in zip(data["clean"], data["noisy"]):
        lo, hi = np.quantile(clean, [0.25, 0.75])
        if hi < 2.0 * lo or lo < 20.0 or hi > 200.0:
            continue  # too little intensity range to see a shape, or near the clipping levels
        res = noisy.astype(np.float64) - clean
        ratios.append(res[clean >= hi].var() / res[clean <= lo].var())
    assert len(ratios) >= 5
    return float(np.median(ratios))


def test_unexpected_noise_follows_the_drawn_shape_and_enters_the_truth():
    kw = {"n": 160, "patch_size": 32, "seed": 4, "progress": False}
    flat = generate(scheme=Scheme(p_scheme=0.0, p_unexpected=1.0, unexpected_sigma=10.0), **kw)
    prnu = generate(scheme=Scheme(p_scheme=0.0, p_unexpected=1.0, unexpected_sigma=10.0, unexpected_shapes=(1.0,)), **kw)
    assert np.array_equal(flat["clean"], prnu["clean"])
    # PRNU-like: the noise added in the bright quarter is >= 2x the dark quarter's in sigma (>= 4x in variance);
    # flat: about the same (the model's own shot noise adds a little)
    assert _bright_to_dark_variance(prnu) > 4.0 > 2.0 > _bright_to_dark_variance(flat)
    for d in (flat, prnu):  # the truth: the image's noise is the model's and the unexpected in quadrature
        assert np.allclose(d["truth_sigma_image"] ** 2, d["truth_sigma_model"] ** 2 + d["unexpected"] ** 2)
        assert np.median(d["unexpected"]) > 8.0  # its RMS over the patch is the drawn 10 DN, less what clipping takes
    assert scheme_of(prnu).unexpected_shapes == (1.0,) and scheme_of({}) == Scheme()


def test_default_scheme_draws_no_shape():
    """One flat shape draws nothing from the generator: datasets of the default scheme stay bit-identical."""
    kw = {"n": 16, "patch_size": 32, "seed": 5, "progress": False}
    plain = generate(scheme=Scheme(), **kw)
    mixed = generate(scheme=Scheme(unexpected_shapes=(0.0, 1.0)), **kw)
    assert np.array_equal(plain["clean"], mixed["clean"]) and not np.array_equal(plain["noisy"], mixed["noisy"])
    assert scheme_of(plain) == Scheme() and scheme_of(mixed).unexpected_shapes == (0.0, 1.0)


def test_train_cli_unexpected_shapes(tmp_path, capsys):
    args = ["train", "--variant", "full_meta", "--out", str(tmp_path), "--steps", "1", "--batch", "2",
            "--patches", "8", "--patch-size", "32", "--threads", "1"]
    assert cli_main(args + ["--unexpected-shapes", "0", "0.5", "1"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["scheme"]["unexpected_shapes"] == [0.0, 0.5, 1.0]
    assert "--unexpected-shapes 0 0.5 1 " in summary["command"]
    assert cli_main(args) == 2 and "corruption scheme" in capsys.readouterr().err  # the dataset is another one
    assert cli_main(args + ["--unexpected-shapes", "3"]) == 2 and "[0, 2]" in capsys.readouterr().err
