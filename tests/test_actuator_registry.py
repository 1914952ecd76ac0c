"""Tests of servotau.actuator.registry: the registry finds one file per effect, each declaring all its parts."""

import importlib
import pkgutil
import sys

import numpy as np
import pytest

from servotau.actuator import (
    EXPERIMENTS,
    ONLINE_SIGNALS,
    Effect,
    Signals,
    builtin_effects,
    effect_names,
    get_effect,
    registry,
)
from servotau.actuator import effects as effects_package
from servotau.errors import IdentificationError

LIBRARY_ORDER = ("coulomb", "coulomb_asym", "stribeck", "viscous_power", "dahl", "lugre", "stiction", "deadzone",
                 "direction_gain", "load_friction", "backlash", "cogging", "thermal_drift", "saturation", "elastic",
                 "motor_lag", "delay")
FILES = sorted(m.name for m in pkgutil.iter_modules(effects_package.__path__) if not m.name.startswith("_"))


def test_registry_finds_every_effect_file_in_library_order():
    """Every file of actuator/effects/ is a built-in effect, in the library's order (rankings break ties by it)."""
    assert sorted(FILES) == sorted(LIBRARY_ORDER)
    assert tuple(e.name for e in builtin_effects()) == LIBRARY_ORDER
    assert tuple(effect_names()[: len(LIBRARY_ORDER)]) == LIBRARY_ORDER


@pytest.mark.parametrize("name", FILES)
def test_each_effect_file_declares_all_its_parts(name):
    """An effect file holds the effect, its order, grid, excitation needs, on-line evaluation and documentation;
    each look-alike has an experiment that separates them."""
    module = importlib.import_module(f"servotau.actuator.effects.{name}")
    e = module.EFFECT
    assert isinstance(e, Effect) and e.name == name and get_effect(name) is e
    assert isinstance(module.ORDER, int)
    assert e.grid == getattr(module, "GRID", e.grid) and (callable(e.grid) or len(e.grid) >= 1)
    assert e.signature and e.description and e.family != "custom" and e.signals
    assert callable(e.needs) and e.online_signals and ONLINE_SIGNALS[name] == e.online_signals
    assert (e.online is not None) != (e.scalar is not None)  # on-line state class, or a scalar formula
    assert not e.history or e.online is not None
    for other in e.confusable:
        assert frozenset((name, other)) in EXPERIMENTS, f"no experiment separates {name} from {other}"
    assert module.__doc__.startswith(f"``{name}``")


@pytest.mark.parametrize("name", [n for n in FILES if get_effect(n).scalar is not None])
def test_scalar_formula_equals_the_regressor(name):
    """An effect without memory evaluates on-line by its scalar formula: the same numbers as the regressor."""
    rng = np.random.default_rng(0)
    n = 50
    cols = {"t": np.arange(n) * 1e-3, "q": rng.normal(size=n), "q_des": rng.normal(size=n),
            "tau": 10 * rng.normal(size=n), "dq": rng.normal(size=n) * 0.05, "u": rng.normal(size=n) * 1e-3}
    e = get_effect(name)
    s = Signals(cols, 1e-3, n)
    for shape in e.grid_for(s):
        batch = e.evaluate(s, shape)
        one = [e.scalar({k: float(v[i]) for k, v in cols.items()}, **shape) for i in range(n)]
        np.testing.assert_allclose(one, batch, rtol=1e-12, atol=1e-15)


def test_adding_an_effect_is_adding_a_file(tmp_path, monkeypatch):
    """A new file in the effects package is found by the registry, placed by its ORDER; a file without its
    parts is refused, naming the file."""
    pkg = tmp_path / "extra_effects"
    pkg.mkdir()
    (pkg / "cubic_torque.py").write_text(
        "from servotau.actuator.registry import Effect\n"
        "ORDER = 15\n"
        "EFFECT = Effect('cubic_torque', lambda s, tau_ref: (s['tau'] / tau_ref) ** 3,\n"
        "                ({'tau_ref': 10.0},), ('tau',))\n"
    )
    monkeypatch.setattr(effects_package, "__path__", [*effects_package.__path__, str(pkg)])
    try:
        names = [e.name for e in registry._discover()]
        assert names[:3] == ["coulomb", "cubic_torque", "coulomb_asym"]
        (pkg / "broken.py").write_text("ORDER = 16\n")
        with pytest.raises(IdentificationError, match="broken.py"):
            registry._discover()
    finally:
        for name in ("cubic_torque", "broken"):
            sys.modules.pop(f"servotau.actuator.effects.{name}", None)


def test_experiments_name_both_effects_of_each_pair():
    """The experiments of the library: 20 look-alike pairs, each written once."""
    assert len(EXPERIMENTS) == 20
    for pair, text in EXPERIMENTS.items():
        assert len(pair) == 2 and all(n in LIBRARY_ORDER for n in pair) and text
