"""Named field-campaign scenarios: how conditions, stated metadata and corruptions evolve over time.

A scenario maps campaign time ``u`` in [0, 1] to a :class:`Step`: the true dynamic metadata, what the
metadata topic states instead (the paper's corrupted-metadata cases), extra image noise, scene
brightness and whether the camera pans. Corruption episodes cover ``EPISODE`` of the campaign.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

#: Campaign-time window of the unexpected-noise episodes.
EPISODE = (0.4, 0.7)
#: Default operating point (true metadata) outside sweeps.
BASE = {"gain_db": 12.0, "exposure_time_s": 0.02, "sensor_temperature_c": 35.0}


@dataclass(frozen=True)
class Step:
    """Conditions of one frame."""

    gain_db: float = BASE["gain_db"]
    exposure_time_s: float = BASE["exposure_time_s"]
    sensor_temperature_c: float = BASE["sensor_temperature_c"]
    #: metadata field -> factor applied to the *stated* value (the camera reports a wrong value)
    stated_factors: dict[str, float] = field(default_factory=dict)
    #: std of extra Gaussian image noise in DN (unexpected noise, not in the model)
    image_noise_dn: float = 0.0
    brightness: float = 1.0
    moving: bool = True

    @property
    def corrupted(self) -> list[str]:
        """Plain-language list of what is corrupted in this frame."""
        out = [f"metadata {k} stated x{v:g}" for k, v in self.stated_factors.items()]
        if self.image_noise_dn:
            out.append(f"image noise +N(0, {self.image_noise_dn:g} DN)")
        return out


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    step: Callable[[float], Step]
    #: a field-like campaign variant (see :mod:`.campaign`): photo world, holds and pans, auto-exposure,
    #: per-frame temperature and vignetting replace ``step`` and the tiled world
    campaign: str | None = None


_SPAN = f"{EPISODE[0]:.0%}-{EPISODE[1]:.0%}"


def _in_episode(u: float) -> bool:
    return EPISODE[0] <= u < EPISODE[1]


def _lerp(a: float, b: float, u: float) -> float:
    return a + (b - a) * u


def _geom(a: float, b: float, u: float) -> float:
    return math.exp(_lerp(math.log(a), math.log(b), u))


def _lab(u: float) -> Step:
    """Static chart, piecewise-constant conditions: 4 gains x 2 exposures x 2 temperatures (16 blocks)."""
    block = min(int(u * 16), 15)
    gains, exposures, temps = (0.0, 6.0, 12.0, 18.0), (0.005, 0.1), (20.0, 60.0)
    return Step(gain_db=gains[block % 4], exposure_time_s=exposures[(block // 4) % 2],
                sensor_temperature_c=temps[block // 8], moving=False)


def _field(u: float) -> Step:
    """Dusk drive: light falls, auto-gain and exposure rise, the sensor warms, unexpected noise mid-way."""
    return Step(
        gain_db=_lerp(0.0, 18.0, u),
        exposure_time_s=_geom(0.005, 0.04, u),
        sensor_temperature_c=_lerp(25.0, 55.0, u),
        brightness=_lerp(1.0, 0.6, u),
        image_noise_dn=5.0 if _in_episode(u) else 0.0,
    )


SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    Scenario("static", "constant conditions, camera at rest", lambda u: Step(moving=False)),
    Scenario("motion", "constant conditions, camera panning with static stretches", lambda u: Step()),
    Scenario("gain_sweep", "gain 0 -> 24 dB", lambda u: Step(gain_db=_lerp(0.0, 24.0, u))),
    Scenario("exposure_sweep", "exposure 1 ms -> 200 ms (geometric)",
             lambda u: Step(exposure_time_s=_geom(0.001, 0.2, u))),
    Scenario("temperature_ramp", "sensor temperature 10 -> 70 degC",
             lambda u: Step(sensor_temperature_c=_lerp(10.0, 70.0, u))),
    Scenario("image_noise", f"paper's xi<0 case: +N(0, 5 DN) image noise during {_SPAN} of the campaign",
             lambda u: Step(image_noise_dn=5.0 if _in_episode(u) else 0.0)),
    Scenario("double_thermal_noise", f"paper's xi>0 case: thermal white noise stated x2 during {_SPAN} of the campaign",
             lambda u: Step(stated_factors={"thermal_white_noise_v_per_sqrt_hz": 2.0} if _in_episode(u) else {})),
    Scenario("double_temperature", f"paper's supplementary case: temperature stated x2 during {_SPAN} of the campaign",
             lambda u: Step(stated_factors={"sensor_temperature_c": 2.0} if _in_episode(u) else {})),
    Scenario("lab", "static chart, 16 blocks of constant gain/exposure/temperature", _lab),
    Scenario("field", "dusk drive: gain, exposure and temperature rise, +N(0, 5 DN) image noise episode", _field),
    # simulated by noise_monitor.profiles.ptc_sim (flat fields and dark frames, not a scene)
    Scenario("ptc", "EMVA 1288 photon-transfer recording for `characterize`: flat fields over an exposure series "
                    "with dark pairs, dark pairs at 3 more temperatures (>= 60 frames; 200 recommended)",
             lambda u: Step(moving=False)),
    Scenario("live_drift", "a live driver: temperature 35 -> 39 degC, auto-exposure +-20 % and auto-gain +-1 dB "
             "oscillating (with simulate-bag --hold 0: new metadata every frame)",
             lambda u: Step(sensor_temperature_c=_lerp(35.0, 39.0, u),
                            exposure_time_s=BASE["exposure_time_s"] * (1.0 + 0.2 * math.sin(8 * math.pi * u)),
                            gain_db=BASE["gain_db"] + math.sin(3 * math.pi * u))),
    Scenario("campaign", "field-like: scikit-image photos and textures, small flat patches, static holds of "
             "5-14 frames and sub-pixel pans, auto-exposure per hold, temperature drifting every frame, "
             "vignetting", lambda u: Step(), campaign="tuned"),
    Scenario("campaign_heldout", "field-like held-out variant: matplotlib/PyWavelets photos, other textures, "
             "holds of 4-18 frames, other pans, exposure and temperature laws", lambda u: Step(),
             campaign="heldout"),
)}


def get_scenario(name: str) -> Scenario:
    """A scenario by name; ValueError lists the known names."""
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}; known: {', '.join(SCENARIOS)}")
    return SCENARIOS[name]
