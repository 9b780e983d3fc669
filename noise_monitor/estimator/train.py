"""Training of every variant on a generated dataset: checkpoints, resume, seed, progress bar."""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from tqdm import tqdm

from .device import resolve_device
from .evidence import N_EVIDENCE
from .features import N_SCALARS, N_SHAPE_TREND, N_SPECTRAL, compact_inputs
from .inference import is_measurable
from .networks import SIGMA_SCALE, ImageNoiseNet, build_network, network_from_checkpoint

HUBER_DELTA_DN = 1.0
#: Hidden sizes of the confidence head added by ``TrainSettings.confidence``.
CONFIDENCE_HIDDEN = (32, 32)


@dataclass
class TrainSettings:
    variant: str
    steps: int = 3000
    batch: int = 32
    lr: float = 1e-3
    seed: int = 0
    width: int | None = None
    depth: int | None = None
    checkpoint_every: int = 250
    #: full_meta only, with ``init``: add a confidence head and train it alone (the measurement frozen)
    confidence: bool = False
    #: also keep every checkpoint's weights as ``step_<N>.pt`` (to choose one on tuning sets)
    keep_checkpoints: bool = False
    #: full_meta fine-tune from ``init`` with a confidence head: weight of a pull (squared log difference) of the
    #: measurement toward the init's reading on the patches the init declines, so that fine-tuning on new
    #: imagery does not move the reading of content no single image can measure (0 = off)
    anchor: float = 0.0
    #: full_meta: the network also takes the shape-trend scalars (``features.shape_trend``); from an ``init``
    #: without them, their input weights start at zero (the init's reading unchanged)
    shape_trend: bool = False
    #: full_meta: the network also takes the line-robust spectral scale (``features.spectral_scale``); from an
    #: ``init`` without it, its input weights start at zero (the init's reading unchanged)
    spectral: bool = False


def meta_norm_of(data: dict[str, np.ndarray]) -> np.ndarray:
    """Normalised metadata (N, 11) of every patch of a dataset."""
    from .data import row_to_meta

    by_group = np.stack([row_to_meta(r).normalized() for r in data["meta_rows"]])
    return by_group[data["group_of"]]


def tensors_for(variant: str, data: dict[str, np.ndarray], chunk: int = 8192, trend: bool = False,
                spectral: bool = False) -> dict[str, torch.Tensor]:
    """Network inputs and targets of a dataset for a variant (full_meta's features in chunks of ``chunk``
    patches: their per-pixel intermediates for a whole large dataset would take twice its maps' memory;
    ``trend`` / ``spectral``: with the shape-trend scalars / the spectral scale)."""
    if variant == "full_meta":
        n = len(data["noisy"])
        maps: np.ndarray | None = None
        rows: dict[str, list[np.ndarray]] = {"scalars": [], "evidence": [], "reference": []}
        for i in range(0, n, chunk):
            m, scalars, phys = compact_inputs(data["noisy"][i:i + chunk], data["tables"], data["group_of"][i:i + chunk],
                                              evidence=True, trend=trend, spectral=spectral)
            if maps is None:
                maps = np.empty((n,) + m.shape[1:], dtype=m.dtype)
            maps[i:i + len(m)] = m
            rows["scalars"].append(scalars)
            rows["evidence"].append(phys["evidence"])
            rows["reference"].append(phys["reference"])
        cat = {k: np.concatenate(v) for k, v in rows.items()}
        return {"maps": torch.from_numpy(maps), "scalars": torch.from_numpy(cat["scalars"]),
                "evidence": torch.from_numpy(cat["evidence"]), "reference": torch.from_numpy(cat["reference"]).float(),
                "target": torch.from_numpy(data["truth_sigma_image"]).float()}
    meta_norm = meta_norm_of(data)
    t = {"patch": torch.from_numpy(data["noisy"][:, None] / np.float32(255.0)), "meta": torch.from_numpy(meta_norm)}
    for k in ("pn", "dcsn", "rn", "xi", "sigma_image"):
        t[k] = torch.from_numpy(data[f"truth_{k}"] / SIGMA_SCALE).float()
    t["total"] = t["sigma_image"]  # DRNE measures the total noise in the image
    return t


def loss_of(variant: str, net: torch.nn.Module, batch: dict[str, torch.Tensor], anchor: float = 0.0) -> torch.Tensor:
    """Training loss. full_meta: Huber on sigma_image plus, with a confidence head, the Gaussian NLL of
    the measurement's log-space residual under the head's predicted error; a batch of the frozen
    measurement's cached outputs (``z``, ``mu``: :func:`head_tensors`) trains the head alone. With
    ``anchor`` and a batch of the init's readings (``anchor_mu``, ``anchor_w``: :func:`anchor_tensors`),
    plus ``anchor`` x the mean weighted squared log difference to them."""
    if variant == "full_meta":
        log_err: torch.Tensor | None
        if "z" in batch:  # the confidence head alone on the frozen measurement's cached outputs
            r, log_err = batch["mu"], cast(ImageNoiseNet, net).log_error(batch["z"], batch["evidence"])
            loss = torch.zeros((), device=r.device)
        else:
            out = net(batch["maps"], batch["scalars"], batch["evidence"])
            r, log_err = (out[:, 0], out[:, 1]) if out.ndim == 2 else (out, None)
            est = batch["reference"] * torch.exp(r.clamp(-6.0, 6.0))
            loss = torch.nn.functional.huber_loss(est, batch["target"], delta=HUBER_DELTA_DN)
            if anchor:
                loss = loss + anchor * (batch["anchor_w"] * (r - batch["anchor_mu"]) ** 2).mean()
        if log_err is not None:
            resid = torch.log(batch["target"] / batch["reference"]) - r.detach()
            log_err = log_err.clamp(-8.0, 4.0)
            loss = loss + (0.5 * (resid / log_err.exp()) ** 2 + log_err).mean()
        return loss
    out = net(batch["patch"], batch["meta"])
    return torch.stack([torch.nn.functional.mse_loss(out[k], batch[k]) for k in out]).mean()


def train(settings: TrainSettings, data: dict[str, np.ndarray], out_dir: Path, resume: bool = False,
          device: str = "auto", threads: int = 2, progress: bool = True, init: Path | None = None) -> Path:
    """Train a variant; writes ``checkpoint.pt`` every ``checkpoint_every`` steps and ``<variant>.pt``.

    ``init``: start from the weights of an earlier ``<variant>.pt`` (fine-tuning; fresh optimiser and
    schedule, its step count and time are added to this run's). The networks are size-agnostic (global
    pooling), so the data may have another patch size than the ``init`` network; its configured
    ``patch_size`` (the size the monitor cuts by default) is kept. The checkpoints record the camera
    effects and sensor fields the data was generated with (``effects``, ``sensor``), so ``load`` builds
    the matching physics prior.
    """
    torch.set_num_threads(threads)
    dev = resolve_device(device)
    out_dir.mkdir(parents=True, exist_ok=True)
    ckpt_path = out_dir / "checkpoint.pt"
    patch_size = int(data["noisy"].shape[-1])
    torch.manual_seed(settings.seed)
    if settings.confidence and (settings.variant != "full_meta" or init is None):
        raise ValueError("a confidence head is trained on a full_meta network given by --init")
    if settings.anchor < 0 or (settings.anchor and settings.confidence):
        raise ValueError("--anchor must be >= 0 and is for fine-tuning the measurement, not with --confidence")
    ck_init = None
    if init is not None:
        if not Path(init).is_file():
            raise FileNotFoundError(f"--init: {init} not found")
        ck_init = torch.load(init, map_location=dev, weights_only=True)
        if settings.anchor and not (ck_init.get("variant") == "full_meta" and ck_init["config"].get("confidence")):
            raise ValueError(f"--anchor: {init} is not full_meta weights with a confidence head (what it declines)")
    elif settings.anchor:
        raise ValueError("--anchor needs --init (the weights whose readings it keeps)")
    net: Any = build_network(settings.variant, patch_size, settings.width, settings.depth)
    # a head of the init weights is kept (and trained along: its loss sees the detached measurement);
    # --confidence trains a new head with the texture evidence in its place
    init_cfg = (ck_init or {}).get("config", {})
    head, evidence = tuple(init_cfg.get("confidence") or ()), int(init_cfg.get("evidence", 0))
    if settings.confidence and ck_init is not None:  # (--confidence needs --init: checked above)
        head, evidence = CONFIDENCE_HIDDEN, N_EVIDENCE
        ck_init = {**ck_init, "state_dict": {k: v for k, v in ck_init["state_dict"].items()
                                              if not k.startswith(("confidence.", "conf_"))}}
    trend = settings.shape_trend or bool(init_cfg.get("shape_trend"))
    spectral = settings.spectral or bool(init_cfg.get("spectral"))
    if (head or trend or spectral) and settings.variant == "full_meta":
        net = ImageNoiseNet(replace(net.cfg, confidence=head, evidence=evidence, shape_trend=trend, spectral=spectral))
    if (trend or spectral) and ck_init is not None:  # the optional scalars follow the base ones, in this order
        at = net.cfg.n_pooled + N_SCALARS
        for key, wanted, extra in (("shape_trend", trend, N_SHAPE_TREND), ("spectral", spectral, N_SPECTRAL)):
            if wanted and not init_cfg.get(key):  # widen the init to take them
                ck_init = {**ck_init, "config": {**ck_init["config"], key: True},
                           "state_dict": with_new_inputs(ck_init["state_dict"], at, extra)}
            at += extra if wanted else 0
    net = net.to(dev)
    trainable = [p for name, p in net.named_parameters() if not settings.confidence or name.startswith("confidence.")]
    for p in net.parameters():
        p.requires_grad_(any(p is q for q in trainable))
    opt = torch.optim.Adam(trainable, lr=settings.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=settings.steps, eta_min=settings.lr * 0.05)
    step, elapsed, prior_steps, prior_s = 0, 0.0, 0, 0.0
    rng = np.random.default_rng(settings.seed)
    if ck_init is not None:
        ck = ck_init
        if ck.get("variant") != settings.variant or _layers(ck["config"]) != _layers(net.cfg.as_dict()):
            raise ValueError(f"--init: {init} is not a {settings.variant} network of the same configuration")
        missing, unexpected = net.load_state_dict(ck["state_dict"], strict=False)
        if unexpected or any(not k.startswith(("confidence.", "conf_")) for k in missing):
            raise ValueError(f"--init: {init} does not fit the network (missing {missing}, unexpected {unexpected})")
        if missing:  # a new confidence head: standardise its inputs on the data
            fit_confidence_inputs(net, data, dev)
        net.cfg.patch_size = int(ck["config"]["patch_size"])  # the operating size stays; see the docstring
        prior_steps, prior_s = ck["step"] + ck.get("prior_steps", 0), ck["elapsed_s"] + ck.get("prior_elapsed_s", 0.0)
    if resume:
        if not ckpt_path.is_file():
            raise FileNotFoundError(f"--resume: no checkpoint at {ckpt_path}")
        ck = torch.load(ckpt_path, map_location=dev, weights_only=True)
        if ck["variant"] != settings.variant:
            raise ValueError(f"--resume: checkpoint is for variant {ck['variant']!r}, not {settings.variant!r}")
        net.load_state_dict(ck["state_dict"])
        opt.load_state_dict(ck["optimizer"])
        sched.load_state_dict(ck["scheduler"])
        step, elapsed = ck["step"], ck["elapsed_s"]
        prior_steps, prior_s = ck.get("prior_steps", 0), ck.get("prior_elapsed_s", 0.0)
        rng.bit_generator.state = ck["rng_state"]
    from .data import camera_of

    effects, sensor = camera_of(data)
    tensors = tensors_for(settings.variant, data, trend=trend, spectral=spectral)
    if settings.confidence:
        tensors = head_tensors(net, tensors, dev)
    if settings.anchor and ck_init is not None:
        tensors.update(anchor_tensors(network_from_checkpoint(ck_init).to(dev), tensors, dev))
    n = len(data["noisy"])
    net.train()
    t0 = time.time() - elapsed
    bar = tqdm(total=settings.steps, initial=step, desc=f"train {settings.variant}", disable=not progress)
    running = None
    while step < settings.steps:
        idx = torch.from_numpy(rng.integers(0, n, settings.batch))
        batch = {k: v[idx].to(dev) for k, v in tensors.items()}
        loss = loss_of(settings.variant, net, batch, settings.anchor)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        step += 1
        running = loss.item() if running is None else 0.98 * running + 0.02 * loss.item()
        bar.update(1)
        bar.set_postfix(loss=f"{running:.4g}")
        if step % settings.checkpoint_every == 0 or step == settings.steps:
            ck = _checkpoint(net, settings, step, time.time() - t0, opt, sched, rng)
            torch.save({**ck, "prior_steps": prior_steps, "prior_elapsed_s": prior_s, "effects": effects,
                        "sensor": sensor}, ckpt_path)
            if settings.keep_checkpoints:
                torch.save({**_checkpoint(net, settings, step, time.time() - t0), "prior_steps": prior_steps,
                            "prior_elapsed_s": prior_s, "effects": effects, "sensor": sensor},
                           out_dir / f"step_{step}.pt")
    bar.close()
    final = {**_checkpoint(net, settings, step, time.time() - t0), "prior_steps": prior_steps, "prior_elapsed_s": prior_s,
             "effects": effects, "sensor": sensor}
    path = out_dir / f"{settings.variant}.pt"
    torch.save(final, path)
    return path


def with_new_inputs(state_dict: dict[str, torch.Tensor], at: int, extra: int) -> dict[str, torch.Tensor]:
    """A full_meta state dict widened to take ``extra`` new scalar inputs at input column ``at`` of the MLP and
    the confidence head: zero weights (and, in the head's standardisation, mean 0 / std 1) for them, so the
    readings are unchanged."""
    out = dict(state_dict)
    for key in ("mlp.0.weight", "confidence.0.weight"):
        if key in out:
            w = out[key]
            out[key] = torch.cat([w[:, :at], w.new_zeros(w.shape[0], extra), w[:, at:]], dim=1)
    for key, fill in (("conf_mean", 0.0), ("conf_std", 1.0)):
        if key in out:
            v = out[key]
            out[key] = torch.cat([v[:at], v.new_full((extra,), fill), v[at:]])
    return out


def _layers(config: dict) -> dict:
    """A network configuration without its operating patch size and confidence head (the measurement's
    weight shapes depend on the rest; weights from before ``shape_trend`` / ``spectral`` have none)."""
    return {"shape_trend": False, "spectral": False,
            **{k: v for k, v in config.items() if k not in ("patch_size", "confidence", "evidence")}}


@torch.no_grad()
def head_tensors(net: ImageNoiseNet, tensors: dict[str, torch.Tensor], dev: Any, chunk: int = 512) -> dict[str, torch.Tensor]:
    """The frozen measurement's outputs on every patch, computed once: the confidence head's raw inputs
    ``z``, the measurement ``mu``, with the evidence, reference and target (what training the head alone needs)."""
    net.eval()
    parts = [net.confidence_inputs(tensors["maps"][i:i + chunk].to(dev), tensors["scalars"][i:i + chunk].to(dev))
             for i in range(0, len(tensors["maps"]), chunk)]
    net.train()
    return {"z": torch.cat([p[1] for p in parts]).cpu(), "mu": torch.cat([p[0] for p in parts]).cpu(),
            **{k: tensors[k] for k in ("evidence", "reference", "target")}}


@torch.no_grad()
def anchor_tensors(init_net: torch.nn.Module, tensors: dict[str, torch.Tensor], dev: Any, chunk: int = 512) -> dict[str, torch.Tensor]:
    """The init network's log-space reading ``anchor_mu`` of every patch and ``anchor_w`` = 1 where its
    confidence head declines the patch (the inference rule), else 0."""
    init_net.eval()
    out = torch.cat([init_net(tensors["maps"][i:i + chunk].to(dev), tensors["scalars"][i:i + chunk].to(dev),
                              tensors["evidence"][i:i + chunk].to(dev)).cpu()
                     for i in range(0, len(tensors["maps"]), chunk)])
    r = out[:, 0].clamp(-6.0, 6.0)
    relative = out[:, 1].clamp(-8.0, 4.0).exp()
    measurable = is_measurable(tensors["reference"] * r.exp() * relative, relative)
    return {"anchor_mu": r, "anchor_w": (~measurable).float()}


@torch.no_grad()
def fit_confidence_inputs(net: ImageNoiseNet, data: dict[str, np.ndarray], dev: Any, n: int = 4096) -> None:
    """Set the confidence head's input standardisation from the first ``n`` patches of the data."""
    maps, scalars, phys = compact_inputs(data["noisy"][:n], data["tables"], data["group_of"][:n], evidence=True,
                                         trend=net.cfg.shape_trend, spectral=net.cfg.spectral)
    z = torch.cat([net.confidence_inputs(torch.from_numpy(maps[i:i + 256]).to(dev),
                                         torch.from_numpy(scalars[i:i + 256]).to(dev))[1]
                   for i in range(0, len(maps), 256)])
    if net.cfg.evidence:
        z = torch.cat([z, torch.from_numpy(phys["evidence"]).to(dev)], dim=1)
    net.conf_mean.copy_(z.mean(dim=0))
    net.conf_std.copy_(z.std(dim=0) + 1e-6)


def _checkpoint(net, settings: TrainSettings, step: int, elapsed: float, opt=None, sched=None, rng=None) -> dict:
    ck = {"variant": settings.variant, "config": net.cfg.as_dict(), "state_dict": net.state_dict(),
          "step": step, "elapsed_s": elapsed, "settings": vars(settings).copy()}
    if opt is not None:
        ck.update(optimizer=opt.state_dict(), scheduler=sched.state_dict(), rng_state=rng.bit_generator.state)
    return ck
