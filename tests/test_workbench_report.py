"""The workbench's HTML report (identification/workbench/report.py, views.py) as a MATLAB System Identification
Toolbox user expects it: correlation bands, units on coefficients and axes, fit in the compare legend, the JSON as
a linked file, no clipped titles; rendered by headless Chromium when the system has it."""

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from support.synthetic import cogging_truth, synthetic_table

from servotau.identification.workbench.data import load_dataset
from servotau.identification.workbench.evaluate import compare
from servotau.identification.workbench.model import parse_spec
from servotau.identification.workbench.report import coefficient_unit, fit_titles, write_report
from servotau.identification.workbench.views import residual_views

CHROMIUM = next((p for p in ("/usr/bin/chromium", "/usr/bin/chromium-browser") if Path(p).exists()), None)


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """A compare report of a 2 s synthetic cogging log with a long model label and a summary; and the text of each
    saved figure (titles, axis labels, legend entries) by file."""
    from servotau.identification.workbench import report as module

    ds = load_dataset(synthetic_table(cogging_truth, seconds=2.0))
    c = compare(ds, parse_spec("coulomb+coulomb_asym+viscous_power+load_friction", ds.signals))
    out = tmp_path_factory.mktemp("report")
    summary = {"heldout": {"fit_percent": c.heldout.fit_percent}, "note": "<not html>"}
    texts: dict[str, list[str]] = {}
    save = module._save

    def spy(fig, path):
        items = []
        for ax in fig.axes:
            items += [ax.get_title(), "axis: " + ax.get_xlabel(), "axis: " + ax.get_ylabel()]
            if ax.get_legend() is not None:
                items += [x.get_text() for x in ax.get_legend().get_texts()]
        texts[path.stem] = items
        return save(fig, path)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(module, "_save", spy)
        path = write_report(out, ds, comparison=c, summary=summary)
    return path, ds, c, texts


def test_report_links_the_json_lists_coefficients_with_units_and_the_fit(report):
    """The summary is a linked JSON file, not a dump; each coefficient has a unit; the fit is in the legend."""
    path, ds, c, texts = report
    page = path.read_text()
    assert '<a href="summary.json">summary.json</a>' in page and "&lt;not html&gt;" not in page
    assert json.loads((path.parent / "summary.json").read_text())["note"] == "<not html>"
    assert "<pre>" not in page
    assert "<td>k_tau</td>" in page and "<td>rad/(N m)</td>" in page and "<td>rad/(rad/s)</td>" in page
    assert page.count("<td>rad/(N m)</td>") == 2  # k_tau and load_friction (phi = |tau| s(dq) [N m])
    assert f"{c.model.spec.label()}: fit {c.heldout.fit_percent:.1f} % (held-out)" in texts["timeseries"]
    assert page.count("<th>unit</th>") == 1
    for png in ("timeseries", "correlation", "heatmap", "residual_torque"):
        assert f'src="{png}.png"' in page and (path.parent / f"{png}.png").stat().st_size > 5000


def test_every_axis_of_every_plot_names_its_unit(report):
    """Each plot's axis labels carry a unit in brackets (or [-] for a correlation)."""
    texts = report[3]
    assert len(texts) >= 7
    for name, items in texts.items():
        labels = [t for t in items if t.startswith("axis: ") and t != "axis: "]  # colour bars have no axis label
        assert labels and all("[" in t for t in labels), (name, labels)


def test_coefficient_units_follow_the_target_and_the_effect():
    assert coefficient_unit("k_tau", "rad", False) == "rad/(N m)"
    assert coefficient_unit("k_v", "N m", False) == "N m/(rad/s)"
    assert coefficient_unit("coulomb", "rad", True) == "rad"
    assert coefficient_unit("direction_gain", "rad", True) == "-"
    assert coefficient_unit("elastic", "rad", True) == "rad/(rad/s^2)"
    assert coefficient_unit("backlash", "rad", True) == "rad/(rad/s^2)"
    assert coefficient_unit("saturation", "rad", True) == "-"
    assert coefficient_unit("thermal_drift", "rad", True) == "rad/(rad/s) with gain 0, - with gain 1"
    from servotau.actuator.registry import effect_names

    assert all("per unit of phi" not in coefficient_unit(e, "rad", True) for e in effect_names())  # every effect
    from servotau.actuator.registry import register_effect, unregister_effect

    register_effect("torque_bump_unit", lambda s, w: s["tau"] / w, grid=[{"w": 1.0}], signals=("tau",),
                    phi_unit="N m")  # a user's effect gives its unit in its registration
    try:
        assert coefficient_unit("torque_bump_unit", "rad", True) == "rad/(N m)"
    finally:
        unregister_effect("torque_bump_unit")


def test_correlation_band_is_1_96_over_sqrt_n(report):
    """The band of a white residual (MATLAB resid): +-1.96/sqrt(N); white noise stays mostly inside it."""
    _, ds, c, texts = report
    v = residual_views(ds, c.residual)
    assert v.n == ds.n and v.confidence == pytest.approx(1.96 / np.sqrt(ds.n))
    band = f"95 % band +-1.96/sqrt(N), N = {ds.n}"
    assert texts["correlation"].count(band) == 2  # on the autocorrelation and on the cross-correlation
    assert {"axis: autocorrelation [-]", "axis: cross-correlation [-]", "axis: lag [s]"} <= set(texts["correlation"])
    white = residual_views(ds, np.random.default_rng(0).standard_normal(ds.n))
    assert np.mean(np.abs(white.autocorrelation[1:]) < white.confidence) > 0.85


def test_long_titles_are_wrapped_inside_their_axes():
    """fit_titles wraps a title wider than its plot (a long model label) onto lines that fit."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(8, 3))
    long = "k_tau + k_v + coulomb + coulomb_asym + viscous_power(delta=0.5) + load_friction: against torque"
    axes[0].set_title(long)
    axes[1].set_title("short")
    fit_titles(fig)
    fig.tight_layout()
    r = fig.canvas.get_renderer()
    for ax in axes:
        title, box = ax.title.get_window_extent(r), ax.get_window_extent(r)
        assert title.width <= box.width and box.x0 - 1 <= title.x0 and title.x1 <= box.x1 + 1
    assert "\n" in axes[0].title.get_text() and axes[1].title.get_text() == "short"
    plt.close(fig)


@pytest.mark.skipif(CHROMIUM is None, reason="no Chromium in the system packages (/usr/bin/chromium): "
                                             "apt-get install chromium to render the report")
def test_report_renders_in_headless_chromium(report, tmp_path):
    """Chromium renders the page: the screenshot is the window's size, not blank, and its images are drawn."""
    path = report[0]
    shot = tmp_path / "page.png"
    profile = tmp_path / "profile"
    proc = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", f"--user-data-dir={profile}",
                           "--hide-scrollbars", "--window-size=1280,2400", f"--screenshot={shot}",
                           path.as_uri()], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and shot.exists(), proc.stderr[-2000:]
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)
    assert img.shape[:2] == (2400, 1280)
    gray = img[..., :3].mean(axis=2)
    assert gray.std() > 0.05  # text and plots, not an empty page
    rows_with_ink = np.mean((gray < 0.9).any(axis=1))
    assert rows_with_ink > 0.5  # the plots fill the page (a missing image leaves blank bands)
    shutil.copy(shot, path.parent / "screenshot.png")  # kept next to the report for a person to look at
