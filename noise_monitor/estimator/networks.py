"""The network family: the paper's DRNE-custom / w/o-Meta / Min-Meta / Full-Meta and the compact
image-noise network of the shipped Full-Meta.

Paper family (Fig. "Noise level estimator vs. proposed", appendix table "Details of the proposed
network"): a 3x3 trunk of residual blocks at full resolution (paper: 2 blocks x 5 convolutions, 64
features), then per output a branch = global max pooling -> concat(metadata subset) -> dense 32-16-8
-> 1. The xi branch sees its own pooled features and the three source sigmas.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import torch
from torch import nn

from ..physics import NORMALIZED_ORDER
from .features import N_SCALARS, N_SHAPE_TREND, N_SPECTRAL

#: Metadata per branch (names of ``CameraMetadata.normalized()`` entries), as listed in issue 3.
FULL_META_BRANCHES: dict[str, tuple[str, ...]] = {
    "pn": ("gain_db", "full_well_e"),
    "dcsn": ("gain_db", "sensor_temperature_c", "exposure_time_s", "full_well_e", "pixel_size_m",
             "dark_signal_fom_na_cm2"),
    "rn": ("gain_db", "sensor_temperature_c", "sensor_type", "full_well_e", "pixel_clock_hz",
           "sense_node_gain_v_per_e", "thermal_white_noise_v_per_sqrt_hz", "sense_node_reset_factor"),
}
MIN_META = ("gain_db", "sensor_temperature_c", "exposure_time_s")
PAPER_VARIANTS = ("drne", "wo_meta", "min_meta", "full_meta_paper")
VARIANTS = ("full_meta",) + PAPER_VARIANTS
#: Output scale: networks predict sigma / SIGMA_SCALE (DN).
SIGMA_SCALE = 16.0


def branch_metadata(variant: str) -> dict[str, tuple[str, ...]]:
    """Metadata fields fed to each sigma branch of a paper-family variant."""
    if variant == "drne":
        return {"total": ()}
    if variant == "wo_meta":
        return {s: () for s in FULL_META_BRANCHES}
    if variant == "min_meta":
        return {s: MIN_META for s in FULL_META_BRANCHES}
    if variant == "full_meta_paper":
        return dict(FULL_META_BRANCHES)
    raise ValueError(f"unknown paper variant {variant!r}; choose from {PAPER_VARIANTS}")


def _index(names: tuple[str, ...]) -> list[int]:
    return [NORMALIZED_ORDER.index(n) for n in names]


class ResidualBlock(nn.Module):
    """``convs`` 3x3 convolutions with ReLU and an identity skip (first conv may change channels)."""

    def __init__(self, c_in: int, c: int, convs: int) -> None:
        super().__init__()
        self.head = nn.Conv2d(c_in, c, 3, padding=1)
        self.body = nn.ModuleList(nn.Conv2d(c, c, 3, padding=1) for _ in range(convs - 1))
        self.act = nn.ReLU(inplace=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h0 = self.act(self.head(x))
        h = h0
        for i, conv in enumerate(self.body):
            h = conv(h)
            if i < len(self.body) - 1:
                h = self.act(h)
        return self.act(h + h0)


def dense_block(n_in: int, hidden: tuple[int, ...]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for n in hidden:
        layers += [nn.Linear(n_in, n), nn.ReLU()]
        n_in = n
    layers.append(nn.Linear(n_in, 1))
    return nn.Sequential(*layers)


@dataclass
class PaperConfig:
    variant: str = "full_meta_paper"
    width: int = 64
    blocks: int = 2
    convs_per_block: int = 5
    dense: tuple[int, ...] = (32, 16, 8)
    patch_size: int = 128

    def as_dict(self) -> dict:
        return asdict(self)


class PaperNet(nn.Module):
    """The paper's estimator family; ``forward(patch01 (N,1,H,W), meta (N,11))`` -> dict of sigma/SCALE."""

    def __init__(self, cfg: PaperConfig) -> None:
        super().__init__()
        self.cfg = cfg
        chans = [1] + [cfg.width] * cfg.blocks
        self.trunk = nn.Sequential(*(ResidualBlock(chans[i], chans[i + 1], cfg.convs_per_block) for i in range(cfg.blocks)))
        self.meta_fields = branch_metadata(cfg.variant)
        self.meta_idx = {k: _index(v) for k, v in self.meta_fields.items()}
        self.branches = nn.ModuleDict({k: dense_block(cfg.width + len(v), cfg.dense) for k, v in self.meta_fields.items()})
        self.has_xi = cfg.variant != "drne"
        if self.has_xi:
            self.xi = dense_block(cfg.width + len(self.branches), cfg.dense)

    @property
    def outputs(self) -> tuple[str, ...]:
        return tuple(self.branches) + (("xi",) if self.has_xi else ())

    def forward(self, patch01: torch.Tensor, meta: torch.Tensor) -> dict[str, torch.Tensor]:
        feat = self.trunk(patch01 - 0.5).amax(dim=(2, 3))
        out = {k: b(torch.cat([feat, meta[:, self.meta_idx[k]]], dim=1)).squeeze(1) for k, b in self.branches.items()}
        if self.has_xi:
            sig = torch.stack([out[k] for k in self.branches], dim=1)
            out["xi"] = self.xi(torch.cat([feat, sig], dim=1)).squeeze(1)
        return out


@dataclass
class CompactConfig:
    """The shipped Full-Meta's image-noise network (sigma_image relative to the physics prediction).

    ``strides`` has one entry per 3x3 convolution; stride-2 layers widen the receptive field (texture
    context) at a quarter of the cost of the layers after them.
    """

    width: int = 16
    strides: tuple[int, ...] = field(default=(1, 2, 1, 2, 1))
    heads: int = 4
    hidden: tuple[int, ...] = field(default=(64, 32))
    patch_size: int = 64
    #: hidden sizes of the confidence head (empty: none; see ``ImageNoiseNet``)
    confidence: tuple[int, ...] = field(default=())
    #: texture-evidence inputs of the confidence head (0: none; ``evidence.N_EVIDENCE``)
    evidence: int = 0
    #: the shape-trend scalars as inputs too (``features.shape_trend``)
    shape_trend: bool = False
    #: the line-robust spectral scale as an input too (``features.spectral_scale``; after the trend's)
    spectral: bool = False

    @property
    def n_pooled(self) -> int:
        """Pooled features of the trunk (mean and RMS per channel, one per attention head); the scalars follow."""
        return 2 * self.width + self.heads

    @property
    def n_scalars(self) -> int:
        """Scalar inputs: ``N_SCALARS``, plus ``features.N_SHAPE_TREND`` with ``shape_trend``, plus
        ``features.N_SPECTRAL`` with ``spectral``."""
        return N_SCALARS + (N_SHAPE_TREND if self.shape_trend else 0) + (N_SPECTRAL if self.spectral else 0)

    def as_dict(self) -> dict:
        return asdict(self)


def default_strides(depth: int) -> tuple[int, ...]:
    """Stride pattern of a ``depth``-layer compact net: every second layer halves the resolution."""
    return tuple(2 if i % 2 else 1 for i in range(depth))


#: Maps of the compact net: box residual and Laplacian residual (both / model sigma), intensity.
N_MAPS = 3


class ImageNoiseNet(nn.Module):
    """Measures the noise actually in a patch as ``log(sigma_image / reference)``.

    Inputs: ``maps`` (N, N_MAPS, H, W) and ``scalars`` (N, ``cfg.n_scalars``) (``features.compact_inputs``).
    A strided 3x3 trunk feeds attention pooling (``heads`` softmax-weighted averages over positions:
    the net learns to read the noise where the patch is flat) and mean / RMS pooling, fused with the
    scalars by an MLP. A zero output means "the noise is the image's reference scale"
    (``features.reference_sigma``); the stated metadata's scale is not an input.

    With ``cfg.confidence`` a second head predicts the log standard deviation of the measurement's own
    error (in log space, trained by Gaussian NLL on the residual of the detached measurement) from the
    pooled features, the scalars, the MLP's last hidden layer, the measurement and, with ``cfg.evidence``,
    the patch's texture evidence (third input ``evidence`` (N, cfg.evidence), ``evidence.texture_evidence``:
    how far its fine-scale content departs from white noise); the output is then (N, 2) =
    [log(sigma_image / reference), log error std] instead of (N,).
    """

    conf_mean: torch.Tensor
    conf_std: torch.Tensor

    def __init__(self, cfg: CompactConfig) -> None:
        super().__init__()
        self.cfg = cfg
        layers: list[nn.Module] = []
        c_in = N_MAPS
        for stride in cfg.strides:
            layers += [nn.Conv2d(c_in, cfg.width, 3, stride=stride, padding=1), nn.ReLU()]
            c_in = cfg.width
        self.convs = nn.Sequential(*layers)
        self.attend = nn.Conv2d(cfg.width, 2 * cfg.heads, 1)
        n_in = cfg.n_pooled + cfg.n_scalars
        mlp: list[nn.Module] = []
        for n in cfg.hidden:
            mlp += [nn.Linear(n_in, n), nn.ReLU()]
            n_in = n
        mlp.append(nn.Linear(n_in, 1))
        self.mlp = nn.Sequential(*mlp)
        if cfg.confidence:
            n_conf = cfg.n_pooled + cfg.n_scalars + n_in + 1 + cfg.evidence
            self.confidence = dense_block(n_conf, cfg.confidence)
            # standardisation of the head's inputs, set from the training data (train.fit_confidence_inputs)
            self.register_buffer("conf_mean", torch.zeros(n_conf))
            self.register_buffer("conf_std", torch.ones(n_conf))

    def confidence_inputs(self, maps: torch.Tensor, scalars: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(measurement (N,), the confidence head's raw inputs (N, n_conf))."""
        f = self.convs(maps)
        value, logit = self.attend(f).flatten(2).chunk(2, dim=1)
        attended = (torch.softmax(logit, dim=2) * value).sum(dim=2)
        pooled = torch.cat([f.mean(dim=(2, 3)), f.square().mean(dim=(2, 3)).sqrt(), attended], dim=1)
        h = torch.cat([pooled, scalars], dim=1)
        z = h
        for layer in list(self.mlp)[:-1]:
            h = layer(h)
        mu = self.mlp[-1](h).squeeze(1)
        return mu, torch.cat([z, h, mu[:, None]], dim=1)

    def forward(self, maps: torch.Tensor, scalars: torch.Tensor, evidence: torch.Tensor | None = None) -> torch.Tensor:
        mu, z = self.confidence_inputs(maps, scalars)
        if not self.cfg.confidence:
            return mu
        return torch.stack([mu, self.log_error(z, evidence)], dim=1)

    def log_error(self, z: torch.Tensor, evidence: torch.Tensor | None) -> torch.Tensor:
        """The confidence head on its raw inputs ``z`` (:meth:`confidence_inputs`) and the evidence."""
        if self.cfg.evidence:
            if evidence is None:
                raise ValueError("this network's confidence head needs the texture evidence as third input")
            z = torch.cat([z, evidence], dim=1)
        return self.confidence((z.detach() - self.conf_mean) / self.conf_std).squeeze(1)


def count_parameters(net: nn.Module) -> int:
    return sum(p.numel() for p in net.parameters())


def build_network(variant: str, patch_size: int, width: int | None = None, depth: int | None = None) -> torch.nn.Module:
    """A fresh network of a variant (``width``/``depth`` override the defaults)."""
    if variant == "full_meta":
        cfg = CompactConfig(patch_size=patch_size)
        cfg.width = width or cfg.width
        cfg.strides = default_strides(depth) if depth else cfg.strides
        return ImageNoiseNet(cfg)
    if variant in PAPER_VARIANTS:
        return PaperNet(PaperConfig(variant=variant, patch_size=patch_size, width=width or 16, blocks=depth or 2,
                                    convs_per_block=3))
    raise ValueError(f"unknown variant {variant!r}; choose from {VARIANTS}")


def network_from_checkpoint(ckpt: dict) -> torch.nn.Module:
    cfg = dict(ckpt["config"])
    if ckpt["variant"] == "full_meta":
        cfg["hidden"], cfg["strides"] = tuple(cfg["hidden"]), tuple(cfg["strides"])
        cfg["confidence"] = tuple(cfg.get("confidence", ()))
        net: torch.nn.Module = ImageNoiseNet(CompactConfig(**cfg))
    else:
        cfg["dense"] = tuple(cfg["dense"])
        net = PaperNet(PaperConfig(**cfg))
    net.load_state_dict(ckpt["state_dict"])
    return net
