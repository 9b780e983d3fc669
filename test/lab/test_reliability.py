"""Bad-input matrix of the lab and the effect plug-ins: plug-in effects that raise or return NaN (in the
model, in `noise-monitor analyze --effect-plugin`), plug-in files that are missing, fail to import or
define nothing, and unusable bags given to analyze.

Expected: an EffectError / ValueError naming the effect and the problem; from the CLI exit code 2 with
that reason on one line of stderr, never a traceback or a NaN in the results.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from noise_monitor.bag.messages import image_msg, metadata_msg
from noise_monitor.bag.simulate import simulate_bag
from noise_monitor.bag.writer import BagWriter
from noise_monitor.cli import main
from noise_monitor.lab.analyze import analyze
from noise_monitor.physics import EffectError, NoiseModel, load_plugin_file, load_profile
from noise_monitor.physics.effects import registry

META = load_profile("icx285").metadata(gain_db=12.0, exposure_time_s=0.01, sensor_temperature_c=30.0)

PLUGINS = {
    "raises.py": '''
from noise_monitor.physics.effects import Effect, Param


class Raises(Effect):
    name = "rel_raises"
    distribution = "gaussian"
    params = (Param("sigma_dn", "DN", 0.5, (0.0, 10.0)),)

    def sigma_dn(self, signal_dn, cond):
        raise RuntimeError("sensor model not calibrated")
''',
    "nan.py": '''
import numpy as np
from noise_monitor.physics.effects import Effect, Param


class ReturnsNan(Effect):
    name = "rel_nan"
    distribution = "gaussian"
    params = (Param("sigma_dn", "DN", 0.5, (0.0, 10.0)),)

    def sigma_dn(self, signal_dn, cond):
        return np.where(np.asarray(signal_dn) > 80.0, np.nan, self.values["sigma_dn"])  # NaN above 80 DN
''',
    "bad_modifier.py": '''
from noise_monitor.physics.effects import Effect, Param


class BadModifier(Effect):
    name = "rel_modifier"
    distribution = "modifier"
    params = (Param("factor", "1", 1.0, (0.5, 2.0)),)

    def modify(self, cond):
        raise KeyError("gain_table")
''',
    "params_int.py": "from noise_monitor.physics.effects import Effect\nclass P(Effect):\n    name = 'rel_p'\n"
                     "    params = 5\n",
    "params_tuple.py": "from noise_monitor.physics.effects import Effect\nclass P(Effect):\n    name = 'rel_p'\n"
                       "    params = (('amplitude', 'DN', 1.0, (0.0, 10.0)),)\n",
    "default_outside.py": "from noise_monitor.physics.effects import Effect, Param\nclass P(Effect):\n"
                          "    name = 'rel_p'\n    params = (Param('amplitude', 'DN', 50.0, (0.0, 10.0)),)\n",
    "same_name.py": "from noise_monitor.physics.effects import Effect, Param\nclass Q(Effect):\n"
                    "    name = 'rel_raises'\n    params = (Param('sigma_dn', 'DN', 0.5, (0.0, 10.0)),)\n",
    "no_sigma.py": "from noise_monitor.physics.effects import Effect, Param\nclass N(Effect):\n"
                   "    name = 'rel_no_sigma'\n    params = (Param('sigma_dn', 'DN', 0.5, (0.0, 10.0)),)\n",
    "import_error.py": "import vendor_sdk_that_is_not_installed\n",
    "nothing.py": "X = 1\n",
}
MESSAGES = {
    "rel_raises": "effect.* rel_raises failed to evaluate: sensor model not calibrated",
    "rel_nan": "rel_nan.* returned a NaN",
    "rel_modifier": "rel_modifier.* failed to evaluate: 'gain_table'",
}


@pytest.fixture(autouse=True)
def _restore_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    """Plug-ins registered by a test are forgotten afterwards (the registry is process-wide)."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


@pytest.fixture(scope="module")
def plugins(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("plugins")
    out = {}
    for name, text in PLUGINS.items():
        (d / name).write_text(text)
        out[name] = d / name
    return out


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Path:
    return simulate_bag(tmp_path_factory.mktemp("lab") / "lab.mcap", "icx285", "gain_sweep", frames=6,
                        width=64, height=48, seed=5, hold_s=0.0)


def run_analyze(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["analyze", *map(str, args), "--quiet"])
    out = capsys.readouterr()
    return code, out.out, out.err


def one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("noise-monitor analyze: error: "), err
    return lines[0]


@pytest.mark.parametrize("file,effect", [("raises.py", "rel_raises"), ("nan.py", "rel_nan")])
def test_failing_plugin_effect_in_the_model_is_named(plugins, file, effect):
    assert load_plugin_file(plugins[file]) == [effect]
    model = NoiseModel(extra=[effect])
    with pytest.raises(EffectError, match=effect):
        model.predict(np.linspace(0, 255, 32), META)
    with pytest.raises(EffectError, match=effect):
        model.simulate(np.full((16, 16), 150.0, np.float32), META, np.random.default_rng(0))


def test_analyze_cli_with_a_raising_plugin_exits_2_naming_the_effect(capsys, tmp_path, bag, plugins):
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--effect-plugin", plugins["raises.py"],
                               "--json", tmp_path / "s.json")
    assert code == 2 and re.search(MESSAGES["rel_raises"], one_line(err))
    assert not (tmp_path / "s.json").exists()  # no partial results


@pytest.mark.parametrize("file,effect,add", [("nan.py", "rel_nan", False), ("bad_modifier.py", "rel_modifier", True)])
def test_analyze_with_a_failing_candidate_or_added_effect_names_it(bag, plugins, file, effect, add):
    """As a diagnosis candidate (NaN would otherwise be listed with a NaN rms error), also with --add-effect
    (as the CLI runs it: plug-ins are always candidates too)."""
    with pytest.raises(EffectError, match=MESSAGES[effect]):
        analyze(bag, "icx285", plugins=[plugins[file]], candidates=[effect], add_effects=[effect] if add else ())


@pytest.mark.parametrize("file,match", [
    ("import_error.py", "effect plug-in .*import_error.py failed to import: No module named 'vendor_sdk_that_is_not_installed'"),
    ("nothing.py", "effect plug-in .*nothing.py defines no Effect subclass with a name"),
    ("missing.py", "effect plug-in file .*missing.py does not exist"),
])
def test_analyze_with_an_unusable_plugin_file(capsys, bag, plugins, file, match):
    path = plugins.get(file, bag.parent / file)
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--effect-plugin", path)
    assert code == 2
    assert re.search(match, one_line(err))


@pytest.mark.parametrize("files,match", [
    (["params_int.py"], "effect 'rel_p': params must be a tuple of Param\\(name, unit, default, \\(lo, hi\\)\\), got 5"),
    (["params_tuple.py"], "effect 'rel_p': params must be a tuple of Param.*got \\(\\('amplitude'"),
    (["default_outside.py"], "effect 'rel_p': parameter 'amplitude' default 50 is outside its bounds \\[0, 10\\]"),
    (["raises.py", "same_name.py"], "same_name.py defines 'rel_raises', which .*raises.py defines too: rename one"),
    (["no_sigma.py"], "effect\\(s\\) rel_no_sigma failed to evaluate: NotImplementedError$"),
])
def test_a_malformed_plugin_is_named_when_it_loads(capsys, bag, plugins, files, match):
    """Until 2026-12-04: a TypeError / AttributeError traceback while fitting, a default outside its bounds
    accepted, a second plug-in of one name silently replacing the first, an empty reason after the colon."""
    args = [a for f in files for a in ("--effect-plugin", plugins[f])]
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--no-estimator", *args)
    assert code == 2 and re.search(match, one_line(err)), err
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--no-estimator", *args[:2], *args[:2])
    assert "defines too" not in err  # one file given twice is one plug-in


def test_analyze_refuses_outputs_it_cannot_or_must_not_write_before_any_work(capsys, tmp_path, bag):
    """An output that is the input bag (until 2026-12-04 --json BAG replaced the bag by the summary), a --report
    that is a file, a --json that is a folder: refused at once, nothing written; a link in the report folder is
    replaced, never followed (it wrote outside the folder)."""
    import hashlib

    before = hashlib.sha256(bag.read_bytes()).hexdigest()
    for flag, extra in (("--json", ()), ("--write-profile", ("--add-effect", "prnu")),
                        ("--write-plugin-skeleton", ())):
        code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--no-estimator", flag, bag, *extra)
        assert code == 2 and "is the input" in one_line(err)
    assert hashlib.sha256(bag.read_bytes()).hexdigest() == before
    (tmp_path / "file").write_text("x")
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--report", tmp_path / "file")
    assert code == 2 and "--report " in one_line(err) and "is a file: name a folder" in one_line(err)
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--json", tmp_path)
    assert code == 2 and "is a folder: name the file to write" in one_line(err)
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--add-effect", "prnu",
                               "--write-profile", tmp_path / "file" / "p.yaml")
    assert code == 2 and "is a file, not a folder" in one_line(err)
    report, outside = tmp_path / "report", tmp_path / "outside.txt"
    report.mkdir()
    outside.write_text("ORIGINAL")
    (report / "summary.json").symlink_to(outside)
    code, _, _ = run_analyze(capsys, bag, "--profile", "icx285", "--no-estimator", "--report", report)
    assert code == 0 and outside.read_text() == "ORIGINAL" and not (report / "summary.json").is_symlink()


def test_analyze_with_unknown_or_out_of_range_added_effects(capsys, bag):
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--add-effect", "no_such_effect")
    assert code == 2 and "unknown effect 'no_such_effect' (a plug-in's? load its file with --effect-plugin); known: " in one_line(err)
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--add-effect", "prnu=-5")
    assert code == 2 and "prnu." in one_line(err) and "is outside" in one_line(err)
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--add-effect", "prnu=lots")
    assert code == 2 and "expected a number or 'fit', got 'lots'" in one_line(err)
    # a close name suggested, the parameters listed, a fixed parameter not fitted, an effect given twice
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--add-effect", "pnru")
    assert code == 2 and "unknown effect 'pnru' (did you mean 'prnu'? " in one_line(err)
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--add-effect", "prnu:sigma_pc=fit")
    assert code == 2 and "has no parameter(s) sigma_pc; its parameters: sigma_pct, seed" in one_line(err)
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--add-effect", "prnu:seed=fit")
    assert code == 2 and "seed cannot be fitted" in one_line(err)
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--add-effect", "prnu", "--add-effect", "prnu=1")
    assert code == 2 and "--add-effect names prnu twice" in one_line(err)
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285", "--add-effect", "pn")  # was before = after, exit 0
    assert code == 2 and "effect 'pn' has no fittable parameter: nothing to fit or set" in one_line(err)


def test_analyze_on_unusable_bags(capsys, tmp_path, bag):
    (tmp_path / "empty.mcap").write_bytes(b"")
    code, _, err = run_analyze(capsys, tmp_path / "empty.mcap", "--profile", "icx285")
    assert code == 2 and "cannot read bag" in one_line(err)
    code, _, err = run_analyze(capsys, tmp_path / "missing.mcap", "--profile", "icx285")
    assert code == 2 and "does not exist" in one_line(err)
    truncated = tmp_path / "cut.mcap"
    truncated.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    code, _, err = run_analyze(capsys, truncated, "--profile", "icx285")
    assert code == 2 and "cut.mcap" in one_line(err)


def test_analyze_on_a_bag_without_measurable_regions(capsys, tmp_path):
    bag = tmp_path / "saturated.mcap"
    with BagWriter(bag) as w:
        for i in range(3):
            stamp = 10**18 + i * 10**8
            w.write("/camera/metadata", metadata_msg(META, stamp, "t"), stamp)
            w.write("/camera/image_raw", image_msg(np.full((64, 64), 255, np.uint8), stamp), stamp)
    code, _, err = run_analyze(capsys, bag, "--profile", "icx285")
    assert code == 2 and "no flat, unclipped image regions to measure noise in" in one_line(err)


def test_analyze_a_still_camera_whose_top_rows_are_black(tmp_path):
    """A lens hood or a night sky: the top rows of every frame at 0 DN. The rest is measured as without them (until
    2026-12-04 the black rows' light gains were 0 / 0 and analyze stopped: "no flat, unclipped image regions")."""
    from rosbags.highlevel import AnyReader

    from noise_monitor.bag.writer import typestore

    src = simulate_bag(tmp_path / "still.mcap", "ev76c661", "static", frames=12, width=96, height=64, seed=4)
    hooded = tmp_path / "hooded.mcap"
    with AnyReader([src], default_typestore=typestore()) as reader, BagWriter(hooded) as w:
        for conn, stamp, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.msgtype == "sensor_msgs/msg/Image":
                pixels = msg.data.reshape(msg.height, msg.step).copy()
                pixels[:16] = 0
                msg.data = pixels.reshape(-1)
            w.write(conn.topic, msg, stamp)
    plain = analyze(src, profile="ev76c661", estimator=None)
    summary = analyze(hooded, profile="ev76c661", estimator=None)
    assert summary["measurement"]["cells"] > 0 and not any(c["significant"] for c in summary["candidates"])
    assert summary["rms_error_dn"] <= max(plain["rms_error_dn"], 0.05)
