"""Lab test settings: candidates are the library's effects only, whatever plug-ins other tests registered;
the outside effects' module; a field campaign analysed by the lab."""
from __future__ import annotations

import importlib.util
import json
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from noise_monitor.bag.simulate import load_truth, simulate_bag
from noise_monitor.cli import main as cli_main
from noise_monitor.physics.effects import registry

#: the effects registered at import (collection time): the library's own, before any test's plug-ins
_BUILTINS = dict(registry._REGISTRY)


@pytest.fixture
def builtins_only(monkeypatch: pytest.MonkeyPatch) -> None:
    """The effect registry as the library ships it (plus what the test itself loads), restored afterwards."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(_BUILTINS))


@pytest.fixture(scope="session")
def outside() -> ModuleType:
    """``outside_effects.py``: effects the library lacks, simulated apart from it, and their plug-ins."""
    spec = importlib.util.spec_from_file_location("outside_effects", Path(__file__).with_name("outside_effects.py"))
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def field_lab(tmp_path: Path) -> Callable[..., dict[str, Any]]:
    """``field_lab(effect=None, **field)``: a clean (or ``effect``) campaign_heldout bag (seed 7, 120 frames of
    320x256 at 10 Hz) recorded under ``field`` conditions (``simulate_bag`` keywords, e.g. ``moving_objects=8``,
    ``vibration_px=0.3``, each recorded in its truth), analysed by ``noise-monitor analyze`` (with
    ``--add-effect NAME=fit`` for the effect): the lab's JSON."""
    def run(effect: str | None = None, **field: Any) -> dict[str, Any]:
        bag = simulate_bag(tmp_path / "field.mcap", "ev76c661", "campaign_heldout", effects=[effect] if effect else [],
                           frames=120, width=320, height=256, fps=10.0, seed=7, **field)
        truth = load_truth(bag)
        assert all(truth[k] == v for k, v in field.items())
        out = tmp_path / "lab.json"
        args = ["analyze", str(bag), "--profile", "ev76c661", "--no-estimator", "--quiet", "--json", str(out)]
        assert cli_main(args + (["--add-effect", f"{effect.split('=')[0]}=fit"] if effect else [])) == 0
        return json.loads(out.read_text())
    return run
