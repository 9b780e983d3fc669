"""The plot of ``noise-monitor evaluate --images ... --plot PNG``: per image and part, the noise the estimator reads
against the noise put in, so a camera engineer sees on which of their scenes (and at which noise levels) the
single-image measurement holds."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .data import metas_of  # noqa: E402
from .user_images import ImageSet  # noqa: E402

PART_TITLES = {"a": "(a) stated model true", "b": "(b) gain stated wrong", "c": "(c) + N(0, 5 DN)"}


def plot_image_set(estimator, image_set: ImageSet, data: dict[str, dict[str, np.ndarray]], floors: list[float],
                   path: Path) -> Path:
    """One panel per image (columns) and part (rows, ``data``: part -> held-out data of ``image_set``):
    sigma_image read by ``estimator`` against the true sigma_image, accepted patches filled, declined ones hollow,
    the stated model's sigma_model as grey crosses; the identity line is a perfect reading (log axes)."""
    parts = list(data)
    n = len(image_set.names)
    fig, axes = plt.subplots(len(parts), n, figsize=(2.6 * n + 1.0, 2.6 * len(parts) + 0.8), squeeze=False,
                             sharex=True, sharey=True)
    truths = np.concatenate([d["truth_sigma_image"] for d in data.values()])
    lo, top = max(float(truths.min()) * 0.7, 0.05), float(truths.max()) * 1.4  # log axes: sigma spans decades
    for row, part in enumerate(parts):
        d = data[part]
        out = estimator.predict(d["noisy"], metas_of(d))
        ok = np.asarray(out.get("measurable", np.ones(len(d["noisy"]), bool)), dtype=bool)
        for k, name in enumerate(image_set.names):
            ax = axes[row, k]
            m = d["source_index"] == k
            truth, read = d["truth_sigma_image"][m], out["sigma_image"][m]
            ax.plot([lo, top], [lo, top], color="0.5", lw=0.8)
            ax.scatter(truth, out["sigma_model"][m], marker="x", s=8, color="0.7", lw=0.6, label="sigma_model (stated)")
            ax.scatter(truth[~ok[m]], read[~ok[m]], s=9, facecolors="none", edgecolors="tab:orange", lw=0.6,
                       label="read, declined")
            ax.scatter(truth[ok[m]], read[ok[m]], s=9, color="tab:blue", label="read, accepted")
            if row == 0:
                ax.set_title(f"{name}\n(own floor {floors[k]:.2f} DN)", fontsize=9)
            if k == 0:
                ax.set_ylabel(f"{PART_TITLES[part]}\nsigma read [DN]", fontsize=9)
            if row == len(parts) - 1:
                ax.set_xlabel("true sigma_image [DN]", fontsize=9)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlim(lo, top)
            ax.set_ylim(lo, top)
            ax.grid(alpha=0.3, which="both")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=9, frameon=False)
    fig.suptitle(f"{estimator.name}: noise read from each patch vs the noise put in (your scenes, "
                 f"{image_set.downsample}x downsampled)", fontsize=10)
    fig.tight_layout(rect=(0, 0.05, 1, 0.95))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
