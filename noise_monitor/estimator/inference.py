"""Inference: ``load(name, device)`` -> an estimator with ``predict(patches_dn, metas)``.

``full_meta`` (shipped): per-source sigma = the analytic model (sequential protocol) on each patch's
5x5-smoothed intensity map with the stated metadata; sigma_model = sqrt(PN^2 + DCSN^2 + RN^2);
sigma_image = the compact network's measurement of the noise actually in the patch; xi = sigma_model -
sigma_image; total = sigma_model (the paper's total without xi). Weights with a confidence head also give
``sigma_image_error`` (the measurement's predicted error, DN) and ``measurable`` (that error <=
``MEASURABLE_ERROR_DN`` and <= ``MEASURABLE_RELATIVE_ERROR`` of sigma_image: a patch whose noise the image
cannot reveal, e.g. under dense pixel-scale texture, is declined rather than read; :func:`clear_decisions`
tells the declined patches whose alarm decision is clear anyway). Every patch also gets
``sigma_image_upper``, an upper bound of its noise from the image alone that holds on any content
(:mod:`.bound`), and ``xi_lower = sigma_model - sigma_image_upper``. The head of the
shipped weights also sees the patch's texture evidence (:mod:`.evidence`). With a camera model of more effects
(``model``, or the effects a network was fine-tuned with), ``extra`` is their joint sigma and sigma_model
includes it. The paper-family variants return their branch outputs (``drne``: total only).

On the CPU, Full-Meta runs on ONNX Runtime from the checkpoint's ONNX companion
(:mod:`.onnx_weights`) without importing torch; torch is imported for CUDA, the torch backend, the
paper-family variants and checkpoints without a companion (exported once, then cached).
"""
from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ..physics import CameraMetadata, NoiseModel
from ..physics.constants import MIN_PATCH
from . import onnx_weights
from .features import N_SCALARS, N_SHAPE_TREND, N_SPECTRAL, compact_inputs
from .physics_prior import EXTRA, SOURCES, PhysicsPrior, group_by_meta

WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
NAMES = ("full_meta", "min_meta", "wo_meta", "drne", "full_meta_paper")
#: A patch is measurable when the predicted error of its sigma_image is at most this (DN) and at most
#: ``MEASURABLE_RELATIVE_ERROR`` of it (a reading of almost no noise under texture has a small error in DN
#: but is no measurement). Chosen on crops of the training photographs and procedural images at 64 px
#: (docs/estimator.md, "Declining what one image cannot measure").
MEASURABLE_ERROR_DN = 0.3
MEASURABLE_RELATIVE_ERROR = 0.3
#: Predicted errors by which |xi| must clear an alarm threshold for a declined patch's decision to be clear
#: (chosen on the tuning sets, docs/estimator.md).
CLEAR_DECISION_K = 2.0
#: Pixels per chunk of a Full-Meta batch on the CPU: the features' per-pixel passes stay in the cache (256
#: patches in one pass ran 20-30 % slower per patch than in chunks of 16-32 at 64 px, 8-32 at 128 px).
CHUNK_PIXELS = 2**17


def is_measurable(error_dn: Any, relative: Any) -> Any:
    """The decline rule: a patch is measurable when its predicted error is at most ``MEASURABLE_ERROR_DN`` and
    at most ``MEASURABLE_RELATIVE_ERROR`` of its sigma_image (numpy arrays or torch tensors)."""
    return (error_dn <= MEASURABLE_ERROR_DN) & (relative <= MEASURABLE_RELATIVE_ERROR)


def clear_decisions(pred: dict[str, np.ndarray], threshold_dn: float) -> np.ndarray:
    """Patches whose alarm decision (|xi| > ``threshold_dn``) is clear given their predicted error, measurable
    or not: | |xi| - threshold | > ``CLEAR_DECISION_K`` errors and the relative error within
    ``MEASURABLE_RELATIVE_ERROR`` (a noisy patch measured to 0.6 DN with xi = -4 DN alarms whatever its error)."""
    err = np.asarray(pred["sigma_image_error"], dtype=float)
    return (np.abs(np.abs(pred["xi"]) - threshold_dn) > CLEAR_DECISION_K * err) & (
        err <= MEASURABLE_RELATIVE_ERROR * np.asarray(pred["sigma_image"], dtype=float))


def validate_patches(patches_dn, min_size: int = MIN_PATCH) -> np.ndarray:
    """float32 (N, H, W) on 0..255 from (N, H, W) or (H, W); clear ValueError otherwise."""
    if not isinstance(patches_dn, np.ndarray):
        raise ValueError(f"patches_dn must be a numpy array, got {type(patches_dn).__name__}")
    if patches_dn.dtype.kind not in "uif":
        raise ValueError(f"patches_dn must be real numbers (float32 DN), got dtype {patches_dn.dtype}")
    x = patches_dn[None] if patches_dn.ndim == 2 else patches_dn
    if x.ndim != 3 or x.shape[0] == 0:
        raise ValueError(f"patches_dn must have shape (N, H, W) with N >= 1, got {patches_dn.shape}")
    if min(x.shape[1:]) < min_size:
        raise ValueError(f"patches must be at least {min_size}x{min_size} px, got {x.shape[1]}x{x.shape[2]}")
    x = x.astype(np.float32, copy=False)
    if not np.all(np.isfinite(x)):
        raise ValueError("patches_dn contains NaN or inf")
    lo, hi = float(x.min()), float(x.max())
    if lo < -1e-3 or hi > 255.0 + 1e-3:
        raise ValueError(f"patches_dn must be on the 0..255 DN scale, got values in [{lo:g}, {hi:g}] "
                         "(scale higher bit depths to 8 bit first)")
    return np.clip(x, 0.0, 255.0)


def validate_metas(metas, n: int) -> list[CameraMetadata]:
    """One CameraMetadata per patch (a single one is shared by all)."""
    if isinstance(metas, CameraMetadata):
        return [metas] * n
    if isinstance(metas, (str, bytes)) or not isinstance(metas, Sequence):
        raise ValueError(f"metas must be a CameraMetadata or a list of them, got {type(metas).__name__}")
    if len(metas) != n:
        raise ValueError(f"got {len(metas)} metadata for {n} patches (give one per patch or a single one)")
    bad = [i for i, m in enumerate(metas) if not isinstance(m, CameraMetadata)]
    if bad:
        raise ValueError(f"metas[{bad[0]}] is {type(metas[bad[0]]).__name__}, not CameraMetadata")
    return list(metas)


INFO_KEYS = ("step", "elapsed_s", "settings")


class _Base:
    name: str
    patch_size: int
    net: Any  # the torch module (None on the ONNX-only fast path)

    def __init__(self, ckpt: dict, device: Any) -> None:
        from .networks import network_from_checkpoint

        self.device = device
        self.net = network_from_checkpoint(ckpt).to(device).eval()
        self.patch_size = int(ckpt["config"]["patch_size"])
        self.name = ckpt["variant"]
        self.info = {k: ckpt[k] for k in INFO_KEYS if k in ckpt}

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name} patch {self.patch_size} on {self.device}>"


BACKENDS = ("auto", "torch", "onnx")


def default_threads() -> int:
    """CPU threads for inference when not given: all cores but one (one stays for message handling)."""
    return max(1, (os.cpu_count() or 2) - 1)


def export_onnx(net: Any, example: tuple[Any, ...]) -> tuple[bytes, list[str]]:
    """``net`` exported to ONNX in memory (dynamic batch and patch size) and its input names."""
    import io

    import torch

    names = [f"in{i}" for i in range(len(example))]
    axes = {n: ({0: "batch", 2: "h", 3: "w"} if t.ndim == 4 else {0: "batch"}) for n, t in zip(names, example)}
    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch's TorchScript exporter deprecation notices
        torch.onnx.export(net, example, buf,  # type: ignore[arg-type]  # a file object is accepted
                          input_names=names, output_names=["out"], dynamic_axes={**axes, "out": {0: "batch"}},
                          dynamo=False)
    return buf.getvalue(), names


def onnx_session(net: Any, example: tuple[Any, ...], threads: int | None = None) -> tuple[Any, list[str]]:
    """An ONNX Runtime CPU session of ``net`` (dynamic batch and patch size), exported in memory."""
    data, names = export_onnx(net, example)
    return onnx_weights.session(data, threads or default_threads()), names


def _compact_example(patch_size: int, n_scalars: int, evidence: int = 0) -> tuple[Any, ...]:
    import torch

    from .networks import N_MAPS

    example = (torch.zeros(2, N_MAPS, patch_size, patch_size), torch.zeros(2, n_scalars))
    return example + ((torch.zeros(2, evidence),) if evidence else ())


class FullMetaEstimator(_Base):
    """Physics-anchored sources plus a learned measurement of the image noise (see module docstring).

    ``backend``: ``torch`` (eager) or ``onnx`` (ONNX Runtime, CPU only); ``auto`` = ONNX Runtime on
    CPU (measured faster here, bench/bench_estimator.py), torch on CUDA.
    """

    def __init__(self, ckpt: dict, device: Any, model: NoiseModel | None = None, backend: str = "auto",
                 threads: int | None = None) -> None:
        super().__init__(ckpt, device)
        self._setup(dict(ckpt.get("effects") or {}), model)
        if backend == "onnx" and device.type != "cpu":
            raise ValueError("the onnx backend runs on CPU only; use backend='torch' with CUDA")
        self.backend = "onnx" if backend == "onnx" or (backend == "auto" and device.type == "cpu") else "torch"
        self._session = None
        if self.backend == "onnx":
            self._session, self._inputs = onnx_session(self.net, self._example(), threads)

    @classmethod
    def from_onnx(cls, session: Any, meta: dict[str, Any], model: NoiseModel | None = None) -> FullMetaEstimator:
        """The estimator of an ONNX companion (CPU, no torch)."""
        est = cls.__new__(cls)
        est.device, est.net, est.backend = "cpu", None, "onnx"
        est.patch_size, est.name, est.info = int(meta["patch_size"]), meta["variant"], dict(meta.get("info") or {})
        est._session, est._inputs = session, [i.name for i in session.get_inputs()]
        est._setup(dict(meta.get("effects") or {}), model)
        return est

    def _setup(self, trained_effects: dict, model: NoiseModel | None) -> None:
        #: the camera effects the network was trained with (empty: the paper's sources only)
        self.trained_effects = trained_effects
        self.prior = PhysicsPrior(model if model is not None else NoiseModel(extra=self.trained_effects))
        lacking = sorted(set(self.trained_effects) - set(self.prior.model.names))
        if lacking:
            warnings.warn(f"estimator weights were trained for a camera with {', '.join(lacking)}, which the given "
                          "noise model lacks: sigma_model and xi will be biased (use the profile the weights were "
                          "fine-tuned for)", stacklevel=4)

    def _example(self) -> tuple[Any, ...]:
        return _compact_example(self.patch_size, self.net.cfg.n_scalars, self.net.cfg.evidence)

    def companion(self, source_sha256: str) -> bytes:
        """This network as an ONNX companion of the checkpoint with that SHA-256 (torch backend objects)."""
        data, _ = export_onnx(self.net, self._example())
        return onnx_weights.with_metadata(data, {
            "source_sha256": source_sha256, "variant": self.name, "patch_size": self.patch_size,
            "effects": self.trained_effects, "info": self.info})

    @property
    def _wants_evidence(self) -> bool:
        return len(self._inputs) > 2 if self._session is not None else bool(self.net.cfg.evidence)

    @cached_property
    def _extra_scalars(self) -> tuple[bool, bool]:
        """Whether the network takes the shape-trend scalars and the spectral scale (``features.shape_trend``,
        ``features.spectral_scale``; asked once, not per call). An ONNX session tells them from its scalar width
        (each combination has its own)."""
        if self._session is not None:
            extra = self._session.get_inputs()[1].shape[1] - N_SCALARS
            return extra in (N_SHAPE_TREND, N_SHAPE_TREND + N_SPECTRAL), extra in (N_SPECTRAL, N_SHAPE_TREND + N_SPECTRAL)
        return bool(self.net.cfg.shape_trend), bool(self.net.cfg.spectral)

    def _run_net(self, *inputs: np.ndarray) -> np.ndarray:
        if self._session is not None:
            return self._session.run(None, dict(zip(self._inputs, inputs)))[0]
        import torch

        with torch.inference_mode():
            r = self.net(*(torch.from_numpy(a).to(self.device) for a in inputs))
        return r.cpu().numpy()

    def predict(self, patches_dn: np.ndarray, metas: CameraMetadata | Sequence[CameraMetadata]) -> dict[str, np.ndarray]:
        x = validate_patches(patches_dn)
        ms = validate_metas(metas, len(x))
        step = max(1, CHUNK_PIXELS // (x.shape[1] * x.shape[2]))
        if len(x) <= step or not str(self.device).startswith("cpu"):  # a GPU takes the batch whole
            return self._predict(x, ms)
        parts = [self._predict(x[i:i + step], ms[i:i + step]) for i in range(0, len(x), step)]
        return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

    def _predict(self, x: np.ndarray, ms: Sequence[CameraMetadata]) -> dict[str, np.ndarray]:
        """:meth:`predict` of validated patches in one pass."""
        groups = group_by_meta(ms)
        tables = np.stack([self.prior.tables(m) for m in groups])
        group_of = np.empty(len(x), dtype=np.int64)
        for g, idx in enumerate(groups.values()):
            group_of[idx] = g
        maps, scalars, phys = compact_inputs(x, tables, group_of, evidence=self._wants_evidence, upper=True,
                                             trend=self._extra_scalars[0], spectral=self._extra_scalars[1])
        inputs = (maps, scalars) + ((phys.pop("evidence"),) if self._wants_evidence else ())
        raw = self._run_net(*inputs).astype(np.float64)
        r = np.clip(raw[:, 0] if raw.ndim == 2 else raw, -6.0, 6.0)
        sigma_image = phys.pop("reference") * np.exp(r)
        out = {s: phys[s] for s in SOURCES + ((EXTRA,) if EXTRA in phys else ())}
        out.update(sigma_model=phys["total"], sigma_image=sigma_image, xi=phys["total"] - sigma_image,
                   total=phys["total"].copy(), sigma_image_upper=phys["upper"], xi_lower=phys["total"] - phys["upper"])
        if raw.ndim == 2:  # confidence head: log-space error std -> DN (first order)
            relative = np.exp(np.clip(raw[:, 1], -8.0, 4.0))
            out["sigma_image_error"] = sigma_image * relative
            out["measurable"] = is_measurable(out["sigma_image_error"], relative)
        return out


class PaperEstimator(_Base):
    """A paper-family network (branch outputs in DN; ``drne``: total only)."""

    def predict(self, patches_dn: np.ndarray, metas: CameraMetadata | Sequence[CameraMetadata]) -> dict[str, np.ndarray]:
        x = validate_patches(patches_dn)
        ms = validate_metas(metas, len(x))
        meta = np.stack([m.normalized() for m in ms])
        import torch

        from .networks import SIGMA_SCALE

        with torch.inference_mode():
            out = self.net(torch.from_numpy(x[:, None] / np.float32(255.0)).to(self.device), torch.from_numpy(meta).to(self.device))
        res = {k: v.cpu().numpy().astype(np.float64) * SIGMA_SCALE for k, v in out.items()}
        if "pn" in res:
            res["total"] = np.sqrt(sum(np.maximum(res[s], 0.0) ** 2 for s in SOURCES))
            res["sigma_image"] = res["total"] - res["xi"]
        else:
            res["sigma_image"] = res["total"]
        return res


def weights_path(name: str, weights_dir: Path | None = None) -> Path:
    if name not in NAMES:
        raise ValueError(f"unknown estimator {name!r}; choose from {NAMES}")
    path = (weights_dir or WEIGHTS_DIR) / f"{name}.pt"
    if not path.is_file():
        raise FileNotFoundError(f"no weights for {name!r} at {path} (train them with `noise-monitor train --variant {name}`)")
    return path


def load(name: str = "full_meta", device: str = "auto", weights: str | Path | None = None,
         model: NoiseModel | None = None, backend: str = "auto", threads: int | None = None
         ) -> FullMetaEstimator | PaperEstimator:
    """Load a trained estimator (bundled weights, or ``weights`` = a .pt file written by training).

    ``model``: the NoiseModel of the physics prior (default: the paper's sources plus the effects the
    weights were trained with, see ``noise-monitor train --profile``); ``backend``: see
    :class:`FullMetaEstimator` (paper-family variants always run in torch); ``threads``: CPU threads of
    the ONNX Runtime session (default: all cores but one).
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    path = Path(weights) if weights is not None else weights_path(name)
    if not path.is_file():
        raise FileNotFoundError(f"weights file {path} not found")
    threads = threads or default_threads()
    if device == "cpu" and backend != "torch":  # the fast path: no torch at all
        found = onnx_weights.find(path, threads)
        if found is not None and found[1].get("variant") == "full_meta":
            return FullMetaEstimator.from_onnx(found[0], found[1], model)
    est = _load_checkpoint(path, device, model, backend, threads)
    if isinstance(est, FullMetaEstimator) and est.backend == "onnx":  # cache the export for the next start
        sha = onnx_weights.sha256_of(path)
        onnx_weights.write(onnx_weights.companions(path, sha)[1], est.companion(sha))
    return est


def _load_checkpoint(path: Path, device: str, model: NoiseModel | None, backend: str,
                     threads: int) -> FullMetaEstimator | PaperEstimator:
    import torch

    from .device import resolve_device

    dev = resolve_device(device)
    try:
        ckpt = torch.load(path, map_location=dev, weights_only=True)
    except Exception as exc:  # truncated, empty or not a torch file: unpickling errors of every kind
        raise ValueError(f"weights file {path} is not a readable checkpoint ({type(exc).__name__}: {exc})") from None
    if not isinstance(ckpt, dict) or ckpt.get("variant") not in NAMES:
        raise ValueError(f"{path} is not an estimator checkpoint")
    try:
        if ckpt["variant"] == "full_meta":
            return FullMetaEstimator(ckpt, dev, model, backend, threads)
        return PaperEstimator(ckpt, dev)
    except (KeyError, TypeError, RuntimeError) as exc:  # missing entries, wrong layer shapes
        reason = " ".join(str(exc).split())  # torch's multi-line message on one line
        raise ValueError(f"{path} is a damaged {ckpt['variant']} checkpoint ({type(exc).__name__}: {reason})") from None
