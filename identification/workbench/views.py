"""Residual views: where the model fails, against each signal (data for the plots and the Rerun views).

Residual ``r = measured - model`` (held-out residuals when available). Binned views give the mean and
the standard deviation of ``r`` per bin and the sample count; bins with fewer than ``MIN_BIN`` samples
are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .data import Dataset

MIN_BIN = 20
V_SPLIT = 0.01  # [rad/s] |dq| below: at rest


@dataclass(frozen=True, eq=False)
class Binned:
    """Residual statistics per bin of one signal: bin centres, mean, std, count."""

    centre: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    count: np.ndarray

    def to_dict(self) -> dict:
        return {k: getattr(self, k).tolist() for k in ("centre", "mean", "std", "count")}


@dataclass(frozen=True, eq=False)
class ResidualViews:
    """Every view of one residual.

    Attributes:
        velocity: By |dq| bins (log-spaced), for ``"dq>0"`` and ``"dq<0"`` (abscissa: dq itself).
        torque: By torque bins for ``"dq>0"``, ``"dq<0"``, ``"rest"`` (None without torque).
        position: By position bins (None without position).
        time: Mean per time window (about 100 windows).
        heatmap: Mean residual on a (velocity, torque) grid, NaN where empty; with its edges.
        lags: Lags [s] of the correlations (sample index if no time).
        autocorrelation: Of the residual at ``lags >= 0``.
        crosscorrelation: Of the residual with each input at ``lags`` (positive: the input leads).
        n: Residual samples the correlations are computed on.
        confidence: Half-width of the 95 % band of a white residual's correlations, ``1.96 / sqrt(n)`` (as
            MATLAB's ``resid``): correlations outside it are significant.
    """

    velocity: dict[str, Binned]
    torque: dict[str, Binned] | None
    position: Binned | None
    time: Binned
    heatmap: np.ndarray | None
    heatmap_dq_edges: np.ndarray | None
    heatmap_tau_edges: np.ndarray | None
    lags: np.ndarray
    autocorrelation: np.ndarray
    crosscorrelation: dict[str, np.ndarray]
    n: int = 0
    confidence: float = float("nan")


def binned(x: np.ndarray, r: np.ndarray, edges: np.ndarray) -> Binned:
    idx = np.digitize(x, edges) - 1
    k = len(edges) - 1
    ok = (idx >= 0) & (idx < k)
    count = np.bincount(idx[ok], minlength=k)
    s1 = np.bincount(idx[ok], weights=r[ok], minlength=k)
    s2 = np.bincount(idx[ok], weights=r[ok] ** 2, minlength=k)
    keep = count >= MIN_BIN
    mean = np.divide(s1, count, out=np.zeros(k), where=count > 0)
    var = np.divide(s2, count, out=np.zeros(k), where=count > 0) - mean**2
    centre = 0.5 * (edges[:-1] + edges[1:])
    return Binned(centre[keep], mean[keep], np.sqrt(np.maximum(var[keep], 0.0)), count[keep])


def _xcorr(a: np.ndarray, b: np.ndarray, lags: np.ndarray) -> np.ndarray:
    a = (a - a.mean()) / (a.std() or 1.0)
    b = (b - b.mean()) / (b.std() or 1.0)
    n = len(a)
    out = np.empty(len(lags))
    for i, k in enumerate(lags):
        out[i] = np.mean(a[k:] * b[: n - k]) if k >= 0 else np.mean(a[: n + k] * b[-k:])
    return out


def residual_views(ds: Dataset, residual: np.ndarray, max_lag_s: float = 0.2) -> ResidualViews:
    """All the views of ``residual`` on ``ds``."""
    s = ds.signals
    r = residual
    dq = s["dq"]
    vmax = float(np.max(np.abs(dq))) or 1.0
    vedges = np.geomspace(1e-3, max(vmax, 2e-3) * 1.0001, 25)
    velocity = {}
    for name, sel, sg in (("dq>0", dq > 0, 1.0), ("dq<0", dq < 0, -1.0)):
        b = binned(np.abs(dq[sel]), r[sel], vedges)
        velocity[name] = Binned(sg * b.centre, b.mean, b.std, b.count)
    torque = heat = de = te = None
    if "tau" in s:
        tau = s["tau"]
        tedges = np.linspace(tau.min(), tau.max() + 1e-9, 31)
        torque = {name: binned(tau[sel], r[sel], tedges)
                  for name, sel in (("dq>0", dq > V_SPLIT), ("dq<0", dq < -V_SPLIT), ("rest", np.abs(dq) <= V_SPLIT))}
        de = np.linspace(-vmax, vmax + 1e-9, 25)
        te = np.linspace(tau.min(), tau.max() + 1e-9, 25)
        i = np.clip(np.digitize(dq, de) - 1, 0, len(de) - 2)
        j = np.clip(np.digitize(tau, te) - 1, 0, len(te) - 2)
        cnt = np.zeros((len(de) - 1, len(te) - 1))
        tot = np.zeros_like(cnt)
        np.add.at(cnt, (i, j), 1.0)
        np.add.at(tot, (i, j), r)
        heat = np.where(cnt >= 5, tot / np.maximum(cnt, 1.0), np.nan)
    position = None
    if "q" in s:
        q = s["q"]
        position = binned(q, r, np.linspace(q.min(), q.max() + 1e-12, 121))
    t = ds.time
    time = binned(t, r, np.linspace(t.min(), t.max() + 1e-9, 101))
    dt = ds.dt or 1.0
    kmax = max(1, min(int(round(max_lag_s / dt)) if ds.dt else 200, len(r) // 4))
    step = max(1, kmax // 100)
    lags = np.arange(-kmax, kmax + 1, step)
    pos = lags[lags >= 0]
    auto = _xcorr(r, r, pos)
    cross = {}
    for name in ("tau", "dq", "q_des"):
        if name in s:
            x = s[name] if name != "q_des" else np.gradient(s["q_des"], dt)
            cross[name if name != "q_des" else "dq_des"] = _xcorr(r, x, lags)
    return ResidualViews(velocity, torque, position, time, heat, de, te, lags * (dt if ds.dt else 1.0),
                         auto, cross, len(r), 1.96 / np.sqrt(len(r)))
