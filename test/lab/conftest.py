"""Lab test settings: candidates are the library's effects only, whatever plug-ins other tests registered;
the outside effects' module."""
from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import pytest

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
