"""Synthetic field campaigns: simulate a camera over a scenario and write a rosbag2 bag + truth sidecar.

Frames are clean scenes (see :mod:`.scenes`) corrupted with ``NoiseModel(...).simulate(mode="joint")``
under the *true* metadata, optionally with extra image noise, then quantised to mono8. The metadata
topic carries the *stated* metadata (which the corrupted scenarios falsify). The sidecar
``<out>.truth.json`` records per frame the true per-source sigmas, the image's total sigma, the paper
model's sigma for the stated metadata and the resulting true xi = sigma_model - sigma_image.
"""
from __future__ import annotations

import json
import math
import numbers
from collections.abc import Iterable
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any, Protocol, TypedDict

import numpy as np
from scipy.signal import lfilter
from tqdm import tqdm

from noise_monitor.estimator.user_images import ImageSet
from noise_monitor.physics import CameraMetadata, CameraProfile, NoiseModel, load_profile
from noise_monitor.physics.metadata import DYNAMIC_FIELDS

from . import campaign
from .lights import banding_depth, pwm_depth, pwm_gain, rolling_shutter_gain
from .messages import camera_info_msg, image_msg, metadata_msg
from .scenarios import SCENARIOS, Step, get_scenario
from .scenes import camera_path, make_world, view
from .writer import STORAGES, BagWriter

__all__ = ["SCENARIOS", "TOPICS", "FieldConditions", "FrameHook", "simulate_bag", "truth_path", "load_truth"]

#: Contract topic names (under the default ``/camera`` namespace).
TOPICS = {"image": "image_raw", "camera_info": "camera_info", "metadata": "metadata"}
#: First frame's stamp: a fixed epoch keeps simulated bags reproducible byte for byte.
START_NS = 1_700_000_000 * 1_000_000_000


def truth_path(bag: str | Path) -> Path:
    """Ground-truth sidecar of a simulated bag: ``<bag>.truth.json``."""
    p = Path(bag)
    return p.with_name(p.name + ".truth.json")


def load_truth(bag: str | Path) -> dict[str, Any]:
    """Read a simulated bag's ground-truth sidecar."""
    p = truth_path(bag)
    if not p.is_file():
        raise FileNotFoundError(f"no ground-truth sidecar {p} (only simulated bags have one)")
    return json.loads(p.read_text())


class FrameHook(Protocol):
    """Camera physics outside the noise model, applied to each frame in sensor coordinates before the
    image noise and quantization: ``hook(index, clean, noisy, true_meta)`` returns the new float frame
    (DN) from the clean view and the model's noisy one (clipped to 0..255); ``truth`` (JSON-able) goes to
    the truth sidecar."""

    truth: dict[str, Any]

    def __call__(self, index: int, clean: np.ndarray, noisy: np.ndarray, meta: CameraMetadata) -> np.ndarray: ...


def _stated(meta, step: Step):
    if not step.stated_factors:
        return meta
    return meta.replace(**{k: getattr(meta, k) * f for k, f in step.stated_factors.items()})


#: Limits of a simulated campaign: image sides (pixels), number of frames, frame rate (Hz). A frame of
#: 8192 x 8192 is simulated in a few GB of memory; larger ones would exhaust it rather than fail cleanly.
MIN_SIDE, MAX_SIDE = 8, 8192
MAX_FRAMES = 1_000_000
MAX_FPS = 10_000.0
#: largest rms vibration (px per axis) of a simulated campaign camera
MAX_VIBRATION_PX = 5.0
#: largest vibration frequency (Hz) during the exposure
MAX_VIBRATION_HZ = 1000.0
#: largest PWM frequency (Hz) of a dimmed LED lamp, and the default fraction of its period it is on
MAX_PWM_HZ, PWM_DUTY = 100_000.0, 0.5
#: largest rms light flicker (%) of a simulated recording
MAX_FLICKER_PCT = 20.0
#: largest share (%) of the scene's light a switched lamp adds, and the mean frames between its switches
MAX_LAMP_PCT, LAMP_MEAN_FRAMES = 100.0, 25
#: largest rms auto-exposure wander (%) of a simulated recording, and its correlation from frame to frame
MAX_AUTO_EXPOSURE_PCT, AUTO_EXPOSURE_CORRELATION = 30.0, 0.8
#: a rolling shutter's line time (s) and the mains frequency (Hz) of lamps seen through it, by default
LINE_TIME_S, MAINS_HZ = 30e-6, 50.0


class FieldConditions(TypedDict, total=False):
    """A recording's field conditions, keywords of :func:`simulate_bag`."""

    vibration_px: float
    vibration_hz: float
    flicker_pct: float
    banding_pct: float
    mains_hz: float
    line_time_s: float
    pwm_hz: float
    pwm_duty: float
    auto_exposure_pct: float
    wobble: bool
    lamp_pct: float


def simulate_bag(
    out: str | Path,
    profile: str | Path | CameraProfile,
    scenario: str,
    effects: Iterable[str] = (),
    frames: int = 60,
    width: int = 320,
    height: int = 256,
    seed: int = 0,
    storage: str = "mcap",
    fps: float = 5.0,
    namespace: str = "/camera",
    hold_s: float = 1.0,
    progress: bool = False,
    hardware_id: str | None = None,
    start_ns: int = START_NS,
    frame_hook: FrameHook | None = None,
    images: ImageSet | None = None,
    photo_share: float = campaign.PHOTO_SHARE,
    moving_objects: int = 0,
    vibration_px: float = 0.0,
    vibration_hz: float = 0.0,
    flicker_pct: float = 0.0,
    banding_pct: float = 0.0,
    mains_hz: float = MAINS_HZ,
    line_time_s: float = LINE_TIME_S,
    pwm_hz: float = 0.0,
    pwm_duty: float = PWM_DUTY,
    auto_exposure_pct: float = 0.0,
    wobble: bool = False,
    lamp_pct: float = 0.0,
) -> Path:
    """Write a simulated bag (see module doc) and its truth sidecar; returns the bag path.

    ``effects`` are registered effect specs (``"prnu"``, ``"prnu=2"``, ``"row_offsets:sigma_dn=1"``)
    added to the profile's own effects and the paper's PN, DCSN, RN in the simulation. Gain, exposure,
    temperature and the stated-metadata corruptions are updated every ``hold_s`` seconds (a camera's
    auto-exposure / temperature read-out rate; 0 = every frame); image noise and motion change per frame.
    A campaign scenario (``scenario.campaign``, see :mod:`.campaign`) sets its own per-frame plan: a photo
    world, static holds and sub-pixel pans, auto-exposure per hold, temperature every frame (``hold_s`` unused).
    ``hardware_id``: the camera's id in the metadata messages (default: the profile name); ``start_ns``: the
    first frame's stamp (a field campaign's bags are recorded at different times). ``frame_hook``: an
    effect outside the noise model (:class:`FrameHook`), e.g. a response non-linearity or amplifier glow;
    it draws from its own random generator, so the model's noise is that of the bag without it. ``images``:
    a campaign's photo panels from these images (a user's own scenes, ``user_images.load_image_set``) instead of
    its variant's photographs; named in the truth sidecar. ``photo_share``: the share of a campaign world's panels that
    are photographs (the others procedural textures; 1: the scenes alone, besides the small flat chart patches).
    ``moving_objects``: that many objects crossing a
    campaign's view (:func:`.campaign.moving_objects`: people or vehicles passing while the camera holds still),
    painted into the clean view before the noise, from their own random generator (the campaign is that of the
    seed without them). ``vibration_px``: a campaign camera that vibrates, its view displaced every frame by an
    independent Gaussian of this rms per axis (:func:`.campaign.vibration`, own generator; the truth's
    ``offset_px`` and ``moving`` stay the nominal pose's, ``shake_px`` holds the displacement). ``vibration_hz``: the
    camera vibrates at this frequency instead, sinusoidally, during each frame's exposure
    (:func:`.campaign.vibration_during_exposure`, own generator): exposures of about half a period or more smear the
    view (motion blur changing from frame to frame; truth ``shake_px`` the mean displacement, ``blur_px`` the rms
    about it). ``flicker_pct``:
    lights that flicker, the scene's brightness scaled every frame by 1 + an independent Gaussian of this rms (%),
    before the noise (own generator; truth ``flicker_gain``). ``banding_pct``: lamps on ``mains_hz`` mains whose light
    is modulated by this depth (%), seen through a rolling shutter of ``line_time_s`` per row
    (:func:`.lights.rolling_shutter_gain`: bands that deepen as the exposure shortens), the frame clock running free
    of the mains (each frame meets the light at a random phase, own generator; truth ``banding_phase`` and the
    exposure-averaged ``banding_depth``). ``pwm_hz``: the lamps are LEDs dimmed by pulse-width modulation at this
    frequency instead, full for ``pwm_duty`` of each period and ``banding_pct`` % dimmer otherwise
    (:func:`.lights.pwm_gain`: trapezoidal bands, sharp-edged at exposures short of a period). ``auto_exposure_pct``:
    a live driver's auto-exposure hunting under steady light, every frame's exposure (and with it the image's
    brightness) off the plan's by a smooth wander of this rms (%) (:func:`auto_exposure_wander`, own generator; the
    metadata report it; truth ``exposure_factor``). ``lamp_pct``: a lamp adding this share (%) to the scene's light,
    switched on and off at random frames (:func:`lamp_switching`, own generator; truth ``lamp_gain``): the light steps
    while the camera may hold still.
    """
    out = Path(out)
    prof = profile if isinstance(profile, CameraProfile) else load_profile(profile)
    scen = get_scenario(scenario)
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if not 1 <= frames <= MAX_FRAMES:
        raise ValueError(f"frames must be in [1, {MAX_FRAMES}], got {frames}")
    for name, side in (("width", width), ("height", height)):
        if not MIN_SIDE <= side <= MAX_SIDE:
            raise ValueError(f"{name} must be in [{MIN_SIDE}, {MAX_SIDE}] pixels, got {side}")
    if not 0 < fps <= MAX_FPS:
        raise ValueError(f"fps must be in (0, {MAX_FPS:g}] Hz, got {fps}")
    if not 0 <= hold_s <= 1e6:
        raise ValueError(f"hold_s must be in [0, 1e6] s, got {hold_s}")
    if storage not in STORAGES:
        raise ValueError(f"storage must be one of {', '.join(STORAGES)}, got {storage!r}")
    for asked, what in ((moving_objects, "moving objects cross a campaign scenario's view"),
                        (vibration_px, "vibration shakes a campaign scenario's camera"),
                        (images is not None, "own images make the photo panels of a campaign scenario"),
                        (photo_share != campaign.PHOTO_SHARE, "the photo share is of a campaign scenario's panels")):
        if asked and not scen.campaign:
            raise ValueError(f"{what}; {scen.name!r} is none "
                             f"(use {', '.join(n for n, sc in SCENARIOS.items() if sc.campaign)})")
    campaign.check_photo_share(photo_share)
    if not 0 <= moving_objects <= 100:
        raise ValueError(f"moving_objects must be 0-100, got {moving_objects}")
    if not 0 <= vibration_px <= MAX_VIBRATION_PX:
        raise ValueError(f"vibration_px must be 0-{MAX_VIBRATION_PX:g} px, got {vibration_px}")
    if not 0 <= vibration_hz <= MAX_VIBRATION_HZ:
        raise ValueError(f"vibration_hz must be 0-{MAX_VIBRATION_HZ:g} Hz, got {vibration_hz}")
    if vibration_hz and not vibration_px:
        raise ValueError("vibration_hz is the frequency of a vibration: give vibration_px too")
    if wobble and not vibration_hz:
        raise ValueError("wobble is a rolling shutter's reading of a vibration at a frequency: give vibration_hz too")
    if not 0 <= flicker_pct <= MAX_FLICKER_PCT:
        raise ValueError(f"flicker_pct must be 0-{MAX_FLICKER_PCT:g} %, got {flicker_pct}")
    if not 0 <= banding_pct <= 100:
        raise ValueError(f"banding_pct must be 0-100 %, got {banding_pct}")
    if not 0 < mains_hz <= 1000:
        raise ValueError(f"mains_hz must be in (0, 1000] Hz, got {mains_hz}")
    if not 0 < line_time_s <= 1e-3:
        raise ValueError(f"line_time_s must be in (0, 1e-3] s, got {line_time_s}")
    if not 0 <= pwm_hz <= MAX_PWM_HZ or not 0 < pwm_duty < 1:
        raise ValueError(f"pwm_hz must be 0-{MAX_PWM_HZ:g} Hz and pwm_duty in (0, 1), got {pwm_hz}, {pwm_duty}")
    if pwm_hz and not banding_pct:
        raise ValueError("pwm_hz dims the lamps whose bands banding_pct sets: give banding_pct too")
    if not 0 <= auto_exposure_pct <= MAX_AUTO_EXPOSURE_PCT:
        raise ValueError(f"auto_exposure_pct must be 0-{MAX_AUTO_EXPOSURE_PCT:g} %, got {auto_exposure_pct}")
    if not 0 <= lamp_pct <= MAX_LAMP_PCT:
        raise ValueError(f"lamp_pct must be 0-{MAX_LAMP_PCT:g} %, got {lamp_pct}")
    if scen.name == "ptc":
        from noise_monitor.profiles.ptc_sim import simulate_ptc

        refused = [name for name, value in (("flicker", flicker_pct), ("banding", banding_pct),
                                            ("auto-exposure", auto_exposure_pct), ("a lamp", lamp_pct),
                                            ("a frame hook", frame_hook))
                   if value]
        if refused:  # a photon-transfer recording is flat fields under a constant light source, by its definition
            raise ValueError(f"the ptc scenario is a photon-transfer recording (a constant light source, its own "
                             f"exposure plan): {', '.join(refused)} not applicable")
        return simulate_ptc(out, prof, effects, frames=frames, width=width, height=height, seed=seed,
                            storage=storage, fps=fps, namespace=namespace, hardware_id=hardware_id, start_ns=start_ns)
    effect_specs = [*(f"{k}:" + ",".join(f"{p}={v}" for p, v in vals.items()) if vals else k
                      for k, vals in prof.effects.items()), *effects]
    sim_model = NoiseModel(extra=effect_specs)
    paper_model = NoiseModel()
    rng = np.random.default_rng(seed)
    # their own generator: the scene, plan and noise stay those of the seed without flicker
    flicker = 1.0 + flicker_pct / 100.0 * np.random.default_rng([seed, 3]).standard_normal(frames)
    band_phase = np.random.default_rng([seed, 4]).uniform(0.0, 2.0 * np.pi, frames)
    hunt = auto_exposure_wander(np.random.default_rng([seed, 5]), frames, auto_exposure_pct)
    lamp = lamp_switching(np.random.default_rng([seed, 7]), frames, lamp_pct)
    us = np.linspace(0.0, 1.0, frames) if frames > 1 else np.zeros(1)
    if scen.campaign:
        world = campaign.make_world(rng, height, width, scen.campaign, None if images is None else images.images,
                                    photo_share)
        plans = campaign.plan(rng, frames, scen.campaign)
        vignette = campaign.vignetting(height, width, campaign.LAWS[scen.campaign].vignetting)
        # their own generator: the campaign's world, plan and noise stay those of the seed without objects
        movers = campaign.moving_objects(np.random.default_rng([seed, 1]), moving_objects, height, width)
        shakes = campaign.vibration(np.random.default_rng([seed, 2]), frames, vibration_px)
        steps = [Step(gain_db=p.gain_db, exposure_time_s=p.exposure_time_s, sensor_temperature_c=p.sensor_temperature_c,
                      brightness=p.brightness, moving=p.moving) for p in plans]
    else:
        world = make_world(rng, height, width)
        held = _held(us, frames, fps, hold_s)
        steps = [_merge(scen.step(float(u)), scen.step(float(h))) for u, h in zip(us, held)]
        positions = np.stack([camera_path(np.array(u), s.moving) for u, s in zip(us, steps)])
    if auto_exposure_pct:
        steps = [replace(s, exposure_time_s=s.exposure_time_s * float(f)) for s, f in zip(steps, hunt)]
    if scen.campaign:  # each frame's displacements over its exposure (one unless the vibration has a frequency)
        paths = (campaign.vibration_during_exposure(np.random.default_rng([seed, 6]),
                                                    [s.exposure_time_s for s in steps], vibration_px, vibration_hz,
                                                    height if wobble else 0, line_time_s)
                 if vibration_hz else list(shakes[:, None, :]))
    # each row's light under the lamps (rows, a frame's exposure and phase) and the bands' depth at an exposure
    depth = banding_pct / 100.0
    lamps, lamps_depth = ((partial(pwm_gain, depth=depth, hz=pwm_hz, duty=pwm_duty, line_s=line_time_s),
                           partial(pwm_depth, depth, hz=pwm_hz, duty=pwm_duty)) if pwm_hz else
                          (partial(rolling_shutter_gain, depth=depth, mains_hz=mains_hz, line_s=line_time_s),
                           partial(banding_depth, depth, mains_hz=mains_hz)))
    ns = namespace.rstrip("/")
    topic = {k: f"{ns}/{v}" for k, v in TOPICS.items()}
    hw = hardware_id or prof.name
    records: list[dict[str, Any]] = []
    bit_depth = prof.bit_depth
    black = float(prof.black_level_dn)
    prev_offset: tuple[float, float] | None = None
    with BagWriter(out, storage=storage) as writer:
        for i, (u, step) in enumerate(tqdm(list(zip(us, steps)), desc=f"simulate {out.name}", unit="frame",
                                           disable=not progress)):
            stamp = start_ns + int(round(i * 1e9 / fps))
            true_meta = prof.metadata(gain_db=step.gain_db, exposure_time_s=step.exposure_time_s,
                                      sensor_temperature_c=step.sensor_temperature_c)
            stated = _stated(true_meta, step)
            if scen.campaign:
                clean, offset = campaign.render(world, plans[i], vignette, paths[i])
                if movers:
                    clean = campaign.paint(clean, movers, i)[0]
            else:
                window, offset = view(world, positions[i], height, width)
                clean = np.clip(window * np.float32(step.brightness), 0.0, 255.0).astype(np.float32)
            if flicker_pct or auto_exposure_pct or lamp_pct:  # the light's flicker and lamp, the exposure's wander
                clean = np.clip(clean * np.float32(flicker[i] * hunt[i] * lamp[i]), 0.0, 255.0).astype(np.float32)
            if banding_pct:
                bands = lamps(height, true_meta.exposure_time_s, float(band_phase[i]))
                clean = np.clip(clean * bands[:, None].astype(np.float32), 0.0, 255.0).astype(np.float32)
            # the camera's pedestal b keeps the noise down to -b below black; its ADC saturates at 255 - b
            noisy, sigmas = sim_model.simulate(clean, true_meta, rng, mode="joint", black_level_dn=black)
            if frame_hook is not None:
                noisy = np.clip(frame_hook(i, clean, noisy, true_meta), -black, 255.0).astype(np.float32)
            if step.image_noise_dn:
                noisy = np.clip(noisy + rng.normal(0.0, step.image_noise_dn, noisy.shape).astype(np.float32),
                                -black, 255)
            img = np.rint(np.clip(noisy + np.float32(black), 0.0, 255.0)).astype(np.uint8)
            # the truth reads the noise as the monitor does (clipped at black) and without the saturation a pedestal
            # brings (the monitor's patches avoid it)
            sigma_image = float(np.std(np.clip(np.rint(noisy), 0.0, 255.0).astype(np.float64) - clean))
            sigma_model = float(paper_model.predict(clean, stated)["total"])
            writer.write(topic["camera_info"], camera_info_msg(height, width, stamp), stamp)
            writer.write(topic["metadata"], metadata_msg(stated, stamp, hw), stamp)
            writer.write(topic["image"], image_msg(img, stamp), stamp)
            records.append({
                "index": i, "stamp_ns": stamp, "u": round(float(u), 6),
                "sigma": {k: round(float(v), 5) for k, v in sigmas.items()},
                "sigma_image": round(sigma_image, 5),
                "sigma_model": round(sigma_model, 5),
                "xi": round(sigma_model - sigma_image, 5),
                "true_metadata": {k: getattr(true_meta, k) for k in DYNAMIC_FIELDS},
                "stated_changes": {k: getattr(stated, k) for k in step.stated_factors},
                "image_noise_dn": step.image_noise_dn,
                "corrupted": step.corrupted,
                "brightness": round(step.brightness, 5),
                "offset_px": list(offset),
                **({"shake_px": [round(float(v), 4) for v in campaign.first_row(paths[i]).mean(axis=0)]} if vibration_px else {}),
                **({"blur_px": round(campaign.smear_px(campaign.first_row(paths[i])), 4)} if vibration_hz else {}),
                **({"wobble_px": round(campaign.wobble_px(paths[i]), 4)} if wobble else {}),
                **({"flicker_gain": round(float(flicker[i]), 6)} if flicker_pct else {}),
                **({"exposure_factor": round(float(hunt[i]), 6)} if auto_exposure_pct else {}),
                **({"lamp_gain": round(float(lamp[i]), 6)} if lamp_pct else {}),
                **({"banding_phase": round(float(band_phase[i]), 6),
                    "banding_depth": round(lamps_depth(true_meta.exposure_time_s), 6)}
                   if banding_pct else {}),
                "moving": prev_offset is not None and offset != prev_offset,
                **({"hold": plans[i].hold} if scen.campaign else {}),
                "mean_dn": round(float(clean.mean()), 3),
            })
            prev_offset = offset
    truth = {
        "bag": out.name, "profile": prof.name, "scenario": scen.name, "description": scen.description,
        "effects": effect_specs, **({"frame_hook": frame_hook.truth} if frame_hook is not None else {}),
        **({"images": list(images.names), "images_key": images.key} if images is not None else {}),
        **({"photo_share": photo_share} if photo_share != campaign.PHOTO_SHARE else {}),
        **({"moving_objects": moving_objects} if moving_objects else {}),
        **({"vibration_px": vibration_px} if vibration_px else {}),
        **({"vibration_hz": vibration_hz} if vibration_hz else {}),
        **({"wobble": True, "line_time_s": line_time_s} if wobble else {}),
        **({"flicker_pct": flicker_pct} if flicker_pct else {}),
        **({"auto_exposure_pct": auto_exposure_pct} if auto_exposure_pct else {}),
        **({"lamp_pct": lamp_pct} if lamp_pct else {}),
        **({"banding_pct": banding_pct, "line_time_s": line_time_s,
            **({"pwm_hz": pwm_hz, "pwm_duty": pwm_duty} if pwm_hz else {"mains_hz": mains_hz})} if banding_pct else {}),
        "seed": seed, "fps": fps, "width": width, "height": height,
        "bit_depth": bit_depth, **({"black_level_dn": prof.black_level_dn} if prof.black_level_dn else {}),
        "storage": storage, "topics": topic, "simulation_mode": "joint",
        "sigma_note": "sigma: per-source std of each source's clipped noise map on the whole frame (DN); "
                      "sigma_image: std(mono8 image - clean) (a black level off, clipped at 0 and 255); "
                      "sigma_model: paper model (pn, dcsn, rn, joint, clip-aware) for the stated metadata; "
                      "xi = sigma_model - sigma_image",
        "episodes": _episodes(records),
        "frames": records,
    }
    truth_path(out).write_text(json.dumps(truth, indent=1))
    return out


def auto_exposure_wander(rng: np.random.Generator, frames: int, rms_pct: float) -> np.ndarray:
    """(frames,) exposure factors of an auto-exposure hunting about its set point: exp of a stationary AR(1)
    series of ``rms_pct`` % rms, correlated ``AUTO_EXPOSURE_CORRELATION`` from frame to frame; ones for 0."""
    z = rng.standard_normal(frames)
    rho = AUTO_EXPOSURE_CORRELATION
    c = math.sqrt(1.0 - rho**2)
    z[0] /= c  # a[0] = z[0]: the series starts stationary
    return np.exp(rms_pct / 100.0 * lfilter([c], [1.0, -rho], z))


def lamp_switching(rng: np.random.Generator, frames: int, pct: float) -> np.ndarray:
    """(frames,) light factors of a lamp adding ``pct`` % to the scene's light, off at the start and switched at each
    frame with probability 1 / ``LAMP_MEAN_FRAMES``; ones for 0."""
    if not pct:
        return np.ones(frames)
    switched = rng.random(frames) < 1.0 / LAMP_MEAN_FRAMES
    switched[0] = False
    return np.where(np.cumsum(switched) % 2 == 1, 1.0 + pct / 100.0, 1.0)


def _held(us: np.ndarray, frames: int, fps: float, hold_s: float) -> np.ndarray:
    """Campaign time at which each frame's metadata was last updated (sample-and-hold every hold_s)."""
    if hold_s == 0 or frames < 2:
        return us
    t = np.arange(frames) / fps
    t_held = np.floor(t / hold_s + 1e-9) * hold_s
    return t_held / t[-1]


def _merge(now: Step, held: Step) -> Step:
    """Per-frame image noise, brightness and motion of ``now`` with the metadata state of ``held``."""
    return Step(gain_db=held.gain_db, exposure_time_s=held.exposure_time_s,
                sensor_temperature_c=held.sensor_temperature_c, stated_factors=held.stated_factors,
                image_noise_dn=now.image_noise_dn, brightness=now.brightness, moving=now.moving)


def _episodes(records: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Contiguous runs of corrupted frames: stamps, what was corrupted, xi and its shift from clean frames."""
    out: list[dict[str, Any]] = []
    for r in records:
        key = tuple(r["corrupted"])
        if not key:
            continue
        if out and out[-1]["corrupted"] == list(key) and out[-1]["end_index"] == r["index"] - 1:
            out[-1].update(end_ns=r["stamp_ns"], end_index=r["index"])
            continue
        out.append({"start_ns": r["stamp_ns"], "end_ns": r["stamp_ns"], "start_index": r["index"],
                    "end_index": r["index"], "corrupted": list(key)})
    clean = [r["xi"] for r in records if not r["corrupted"]]
    baseline = float(np.mean(clean)) if clean else 0.0
    for ep in out:
        xi = [r["xi"] for r in records[ep["start_index"]:ep["end_index"] + 1]]
        ep["mean_xi"] = round(float(np.mean(xi)), 4)
        ep["xi_shift"] = round(ep["mean_xi"] - baseline, 4)  # relative to the uncorrupted frames
        ep["xi_sign"] = "+" if ep["xi_shift"] > 0 else "-"
    return out
