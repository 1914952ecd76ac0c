"""The encoder's resolution read off the log, and no effect named within its rounding error."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from servotau.identification.workbench import diagnose, load_dataset, parse_spec
from servotau.identification.workbench.resolution import encoder_resolution, quantisation_floor


def test_the_lattice_of_a_quantised_angle_is_its_resolution():
    res = 2 * math.pi / 2**13
    t = np.linspace(0.0, 10.0, 5000)
    q = np.round((0.4 * np.sin(t) + 0.123) / res) * res
    assert math.isclose(encoder_resolution(q), res, rel_tol=1e-9)
    assert math.isclose(quantisation_floor(res), res / math.sqrt(12))


def test_an_unquantised_angle_has_no_resolution():
    t = np.linspace(0.0, 10.0, 5000)
    assert encoder_resolution(0.4 * np.sin(t) + 1e-7 * np.random.default_rng(0).normal(size=t.size)) == 0.0
    assert encoder_resolution(np.zeros(10)) == 0.0


def test_clean_plants_with_a_coarse_encoder_raise_no_alarm():
    """The independent plant family's clean servo, its encoder at 2^13 counts per turn: holds that return to one
    angle share one rounding offset, which holding-versus-moving terms and the probes fit. No effect is named; what
    the probes remove within the rounding error is said."""
    from servotau.experiments import plant_family as pf

    plants = [replace(pf.draw_plant(s, hidden=(), period=1e-3, duration=12.0), res=2 * math.pi / 2**13)
              for s in (1089, 1090)]
    checks = []
    for plant, true in zip(plants, pf.simulate(plants, 12.0), strict=True):
        ds = load_dataset(dict(pf.measure(plant, true)))
        assert math.isclose(ds.preprocessing["q"]["resolution"], plant.res, rel_tol=1e-6)
        assert any(n.startswith("q: quantised to") for n in ds.notes)
        d = diagnose(ds, parse_spec("paper", ds.signals))
        assert d.verdict != "missing_effect"
        checks += d.checks
    assert any("within the encoder's rounding error" in c for c in checks)
