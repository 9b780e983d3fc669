"""Effect plug-ins: loaded from a Python file and from the `noise_monitor.effects` entry-point group."""
from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from noise_monitor.physics import EffectError, NoiseModel, load_plugin_file, load_profile
from noise_monitor.physics.effects import available, registry

PLUGIN = textwrap.dedent('''
    """A user's effect: amplifier glow, temporal noise growing with the exposure time."""
    import numpy as np
    from noise_monitor.physics.effects import Effect, Param

    class AmplifierGlow(Effect):
        name = "amp_glow"
        params = (Param("sigma_per_s", "DN/s", 20.0, (0.0, 1000.0), description="glow noise per second"),)
        description = "Amplifier glow: temporal noise proportional to the exposure time."
        signature = "noise growing linearly with exposure: amplifier glow {sigma_per_s:.0f} DN/s"

        def sigma_dn(self, signal_dn, cond):
            return np.broadcast_to(self.sigma_per_s * cond.exposure_time_s, np.shape(signal_dn))
''')


@pytest.fixture(autouse=True)
def _restore_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """Plug-ins registered here must not leak into other tests of the session."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


@pytest.fixture
def plugin_file(tmp_path: Path) -> Path:
    path = tmp_path / "glow.py"
    path.write_text(PLUGIN)
    return path


def test_plugin_from_file_is_registered_and_used(plugin_file: Path) -> None:
    assert load_plugin_file(plugin_file) == ["amp_glow"]
    assert "amp_glow" in available()
    meta = load_profile("icx285").metadata(gain_db=0.0, exposure_time_s=0.1, sensor_temperature_c=20.0)
    base = NoiseModel()
    model = NoiseModel(extra=["amp_glow=30"])
    clean = np.tile(np.linspace(80.0, 84.0, 256, dtype=np.float32), (256, 1))
    pred = model.predict(clean, meta)
    assert pred["amp_glow"] == pytest.approx(3.0, rel=1e-3)  # 30 DN/s * 0.1 s
    assert pred["total"] ** 2 == pytest.approx(base.predict(clean, meta)["total"] ** 2 + 9.0, rel=0.01)
    _, mc = model.simulate(clean, meta, np.random.default_rng(0))
    assert mc["amp_glow"] == pytest.approx(3.0, rel=0.03)
    assert mc["total"] == pytest.approx(pred["total"], rel=0.03)
    glow = model.effects[-1]
    assert glow.reading() == "noise growing linearly with exposure: amplifier glow 30 DN/s"


def test_plugin_from_entry_point(tmp_path: Path, plugin_file: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pkg = tmp_path / "site"
    (pkg / "glowpkg").mkdir(parents=True)
    (pkg / "glowpkg" / "__init__.py").write_text(PLUGIN.replace('"amp_glow"', '"amp_glow_ep"'))
    dist = pkg / "glowpkg-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: glowpkg\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[noise_monitor.effects]\namp_glow_ep = glowpkg:AmplifierGlow\n")
    monkeypatch.syspath_prepend(str(pkg))
    monkeypatch.setattr(registry, "_entry_points_loaded", False)
    assert "amp_glow_ep" in available()
    assert NoiseModel(extra=["amp_glow_ep"]).names[-1] == "amp_glow_ep"
    sys.modules.pop("glowpkg", None)


def test_broken_plugins_give_clear_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.py"
    bad.write_text(textwrap.dedent('''
        import numpy as np
        from noise_monitor.physics.effects import Effect

        class Raises(Effect):
            name = "raises"
            def sigma_dn(self, signal_dn, cond):
                raise RuntimeError("sensor model exploded")

        class GivesNaN(Effect):
            name = "gives_nan"
            def sigma_dn(self, signal_dn, cond):
                return np.full(np.shape(signal_dn), np.nan)
    '''))
    assert sorted(load_plugin_file(bad)) == ["gives_nan", "raises"]
    meta = load_profile("generic").metadata(gain_db=0.0, exposure_time_s=0.01, sensor_temperature_c=20.0)
    with pytest.raises(EffectError, match="'raises' failed to evaluate: sensor model exploded"):
        NoiseModel(extra=["raises"]).predict(100.0, meta)
    with pytest.raises(EffectError, match="gives_nan.*NaN"):
        NoiseModel(extra=["gives_nan"]).predict(100.0, meta)
    with pytest.raises(EffectError, match="'raises' failed to sample"):
        NoiseModel(extra=["raises"]).simulate(np.zeros((8, 8)), meta, np.random.default_rng(0))
    with pytest.raises(EffectError, match="does not exist"):
        load_plugin_file(tmp_path / "missing.py")
    (tmp_path / "syntax.py").write_text("def broken(:\n")
    with pytest.raises(EffectError, match="failed to import"):
        load_plugin_file(tmp_path / "syntax.py")


def test_broken_modifier_and_quantization_plugins_are_named(tmp_path: Path) -> None:
    bad = tmp_path / "bad_modifiers.py"
    bad.write_text(textwrap.dedent('''
        from noise_monitor.physics.effects import Effect

        class BadModifier(Effect):
            name = "bad_modifier"
            distribution = "modifier"
            def modify(self, cond):
                return {}["gain"]

        class NegativeGain(Effect):
            name = "negative_gain"
            distribution = "modifier"
            def modify(self, cond):
                return cond.replace(gain=-1.0)

        class BadStep(Effect):
            name = "bad_step"
            distribution = "quantization"
            def lsb_dn(self, cond):
                return float("nan")
    '''))
    load_plugin_file(bad)
    meta = load_profile("generic").metadata(gain_db=0.0, exposure_time_s=0.01, sensor_temperature_c=20.0)
    with pytest.raises(EffectError, match="'bad_modifier' failed to modify: 'gain'"):
        NoiseModel(extra=["bad_modifier"]).predict(100.0, meta)
    with pytest.raises(EffectError, match="'negative_gain' produced impossible conditions"):
        NoiseModel(extra=["negative_gain"]).simulate(np.zeros((8, 8)), meta, np.random.default_rng(0))
    with pytest.raises(EffectError, match="'bad_step' returned an invalid quantization step"):
        NoiseModel(extra=["bad_step"]).predict(100.0, meta)


API = textwrap.dedent('''
    import numpy as np
    from noise_monitor.physics.effects import Effect, Param

    class CornerNoise(Effect):
        """Temporal noise concentrated in the top-left corner (position on the sensor)."""
        name = "corner_noise"
        spatial = True
        params = (Param("sigma_dn", "DN", 4.0, (0.0, 50.0)),)
        def sigma_dn(self, signal_dn, cond):
            sig = self.sigma_dn_value() * np.exp(-np.hypot(cond.where.y, cond.where.x) / 0.3)
            return np.broadcast_to(sig, np.broadcast_shapes(np.shape(signal_dn), np.shape(sig)))
        def sigma_dn_value(self):
            return self.values["sigma_dn"]

    class RowFlicker(Effect):
        """Row offsets that change from frame to frame."""
        name = "row_flicker"
        structure = "row"
        params = (Param("sigma_dn", "DN", 2.0, (0.0, 50.0)),)
        def sigma_dn(self, signal_dn, cond):
            return np.broadcast_to(self.values["sigma_dn"], np.shape(signal_dn))

    class Compress(Effect):
        """A response losing slope towards full well (reduces the noise there)."""
        name = "compress"
        distribution = "response"
        params = (Param("strength", "1", 0.6, (0.0, 1.0)),)
        def slope(self, signal_dn, cond):
            return 1.0 - self.strength * (np.asarray(signal_dn, dtype=float) / 255.0) ** 2
''')


@pytest.fixture
def api_plugins(tmp_path: Path) -> list[str]:
    path = tmp_path / "api.py"
    path.write_text(API)
    return load_plugin_file(path)


def test_spatial_effect_sees_pixel_positions_and_averages_without_them(api_plugins: list[str]) -> None:
    meta = load_profile("ev76c661").metadata(gain_db=0.0, exposure_time_s=0.01, sensor_temperature_c=20.0)
    model = NoiseModel(["corner_noise"])
    flat = np.full((128, 160), 100.0, dtype=np.float32)
    frames = np.stack([model.simulate(flat, meta, np.random.default_rng(s), per_source=False)[0] for s in range(8)])
    var = frames.var(axis=0, ddof=1)
    assert var[:16, :16].mean() > 5.0 and var[-16:, -16:].mean() < 0.01  # the corner is noisy, the rest is not
    # without a position, predict gives the sensor average; the frame's variance is that average
    assert model.predict(100.0, meta)["total"] ** 2 == pytest.approx(float(var.mean()), rel=0.05)


def test_row_structured_temporal_noise(api_plugins: list[str]) -> None:
    meta = load_profile("ev76c661").metadata(gain_db=0.0, exposure_time_s=0.01, sensor_temperature_c=20.0)
    model = NoiseModel(["row_flicker"])
    flat = np.full((256, 64), 100.0, dtype=np.float32)
    a, b = (model.simulate(flat, meta, np.random.default_rng(s), per_source=False)[0] for s in (1, 2))
    d = a - b
    assert np.all(d.std(axis=1) == 0.0)  # constant along each row
    assert d[:, 0].var() == pytest.approx(2 * 2.0**2, rel=0.25)  # new offsets every frame
    assert model.predict(100.0, meta)["row_flicker"] == pytest.approx(2.0)


def test_response_reduces_the_noise_analytic_and_monte_carlo_agree(api_plugins: list[str]) -> None:
    meta = load_profile("ev76c661").metadata(gain_db=12.0, exposure_time_s=0.01, sensor_temperature_c=30.0)
    model = NoiseModel(extra=["compress"])
    for v in (40.0, 200.0):
        pred = model.predict(v, meta)
        linear = NoiseModel().predict(v, meta)["total"]
        slope = 1.0 - 0.6 * (v / 255.0) ** 2
        assert pred["total"] == pytest.approx(slope * linear, rel=0.02)
        assert pred["compress"] == pytest.approx(pred["total"] - linear)  # signed change, < 0
        assert pred["compress"] < 0
        _, mc = model.simulate(np.full((256, 256), v, dtype=np.float32), meta, np.random.default_rng(0))
        assert mc["total"] == pytest.approx(pred["total"], rel=0.03)


def test_unknown_structure_and_distribution_are_refused(tmp_path: Path) -> None:
    bad = tmp_path / "bad_api.py"
    bad.write_text(textwrap.dedent('''
        from noise_monitor.physics.effects import Effect

        class Diagonal(Effect):
            name = "diagonal"
            structure = "diagonal"
    '''))
    with pytest.raises(EffectError, match="unknown structure .diagonal.; choose from pixel, row, column"):
        load_plugin_file(bad)
