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
