"""Oracle detectability of a plant family log's hidden effects: the most any model term could remove.

The clean plant of :mod:`.plant_family` obeys the paper's model exactly, ``q_des - q_m = tau_j / K + (D / K) dq_m``.
On the TRUE signals of :func:`~.plant_family.simulate`, the residual (:func:`servo_residual`)::

    r = q_des - q_m - tau_log / K - (D / K) dq_m       [rad]

with ``tau_log = tau_j + thermal_offset`` (the noise-free torque the log records) is therefore exactly what the
hidden effects add to the servo error the paper model sees: a delayed command (``q_des(t) - q_des(t - d)``), a
lagging, clipped or dead-zoned motor torque, friction, the motor-side inertia of a backlash joint, the thermal
gain drop and torque offset. It is 0 on a clean plant (to rounding: the state and the torque are recorded at the
same instant).

:func:`oracle_gain` fits the paper model (``tau``, ``dq``: the workbench's own preprocessed signals of the
measured log, least squares, no constant) with and without ``r`` as an extra column, held out on the workbench's
blocked folds (:func:`~servotau.identification.data.folds_of`), and returns ``1 - E(base + r) / E(base)`` with
``E`` the pooled held-out RMS error: the workbench's own ``heldout_gain`` definition, so that it compares with
its materiality threshold ``MIN_GAIN``. The column is ``r`` itself or ``r`` through the centred Savitzky-Golay
filter the workbench smoothed the log's torque with, whichever removes more: an effect borne by the joint torque
(backlash: the motor inertia's torque chatters in the contact) reaches the smoothed model only through that
filter, and the raw column's chatter, which the servo error does not contain, would hide it. An effect whose
oracle gain is below ``MIN_GAIN`` cannot be named on that log by any term, however exact: it is below what the
log's noise and quantisation let anyone see.

For a pair of hidden effects, :func:`effect_residuals` gives each effect's ``r`` from the same plant simulated
with that effect alone (same parameters, command and grid), and the pair's ``r`` less the other effect's (the
interaction attributed to this one); the better of the two is measured on the pair's log, where the other
effect's error is unmodelled, as the workbench ranks each candidate against the base model. Taking the best
candidate column errs toward calling an effect detectable, i.e. toward blaming the workbench for a miss.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import savgol_filter

from .plant_family import RECORD, Plant, simulate


def servo_residual(plant: Plant, true: dict) -> np.ndarray:
    """``r`` [rad] on the 1 ms grid of ``true`` (see the module doc)."""
    tau_log = true["tau"] + true["thermal_offset"]
    return true["q_des"] - true["q"] - tau_log / plant.K - plant.D / plant.K * true["dq"]


def alone(plant: Plant, effect: str) -> Plant:
    """``plant`` with only ``effect`` hidden (same parameters, command and noise seed)."""
    return replace(plant, hidden=(effect,), effect={effect: plant.effect[effect]})


def singles(plants: list[Plant]) -> list[tuple[int, str, Plant]]:
    """``(index, effect, plant with that effect alone)`` for each effect of each pair among ``plants``."""
    return [(i, e, alone(p, e)) for i, p in enumerate(plants) if len(p.hidden) > 1 for e in p.hidden]


def effect_residuals(plants: list[Plant], trues: list[dict],
                     alone_trues: list[dict] | None = None) -> list[dict[str, list[np.ndarray]]]:
    """Per plant, ``{effect: [r, ...]}``: the candidate oracle columns of each hidden effect, and ``"all"``: the
    plant's own ``r``. A single effect's is the plant's ``r``; each effect ``e`` of a pair gets two, from the plant
    simulated with each effect alone (``alone_trues``: :func:`simulate` of :func:`singles`' plants, in one batch;
    simulated here when None): ``r`` of ``e`` alone, and the pair's ``r`` less that of the other effect alone (the
    interaction of the two attributed to ``e``)."""
    out: list[dict[str, list[np.ndarray]]] = []
    for p, tr in zip(plants, trues, strict=True):
        r = servo_residual(p, tr)
        out.append({"all": [r], **({p.hidden[0]: [r]} if len(p.hidden) == 1 else {})})
    pairs = singles(plants)
    if pairs:
        if alone_trues is None:
            alone_trues = simulate([s[2] for s in pairs], len(trues[0]["t"]) * RECORD)
        own = {(i, e): servo_residual(p, tr) for (i, e, p), tr in zip(pairs, alone_trues, strict=True)}
        for (i, e), r_e in own.items():
            others = [r for (j, f), r in own.items() if j == i and f != e]
            out[i][e] = [r_e, out[i]["all"][0] - sum(others)]
    return out


def _heldout_rms(x: np.ndarray, y: np.ndarray, folds) -> float:
    scale = np.linalg.norm(x, axis=0)
    x = x / np.where(scale > 0, scale, 1.0)
    pred = np.full(len(y), np.nan)
    for f in folds:
        coef, *_ = np.linalg.lstsq(x[f.train], y[f.train], rcond=None)
        pred[f.test] = x[f.test] @ coef
    ok = np.isfinite(pred)
    return float(np.sqrt(np.mean((y[ok] - pred[ok]) ** 2)))


@dataclass(frozen=True)
class PaperFit:
    """The paper model on one workbench dataset, shared by every oracle column of the log.

    Attributes:
        columns: The dataset's ``tau`` [N m] and ``dq`` [rad/s], side by side.
        folds: The workbench's blocked folds of the dataset.
        error: The paper model's pooled held-out RMS error [rad].
    """

    columns: np.ndarray
    folds: list
    error: float


def paper_fit(ds) -> PaperFit:
    """The paper model's held-out error on ``ds``: the denominator of every :func:`oracle_gain` of the log."""
    from servotau.identification.data import folds_of

    columns = np.column_stack([ds.signals["tau"], ds.signals["dq"]])
    folds = folds_of(ds)
    return PaperFit(columns, folds, _heldout_rms(columns, ds.target, folds))


def oracle_gain(ds, t_true: np.ndarray, rs: list[np.ndarray], base: PaperFit | None = None) -> float:
    """Held-out gain over the paper model of the best oracle column of ``rs`` (each on the time grid ``t_true``
    [s]), on the workbench dataset ``ds`` of the measured log (``r`` is read at the dataset's own times, so
    dropped or resampled rows stay aligned); ``base``: :func:`paper_fit` of ``ds``, computed here when None."""
    base = paper_fit(ds) if base is None else base
    if not base.error > 0:
        return 0.0
    cols = [np.interp(ds.signals["t"], t_true, r) for r in rs]
    pre = ds.preprocessing.get("tau", {})
    if pre.get("source") == "smoothed" and pre.get("window", 0) > pre.get("order", 2) + 1:
        cols += [savgol_filter(c, int(pre["window"]), int(pre.get("order", 2))) for c in cols]
    return max(1.0 - _heldout_rms(np.column_stack([base.columns, c]), ds.target, base.folds) / base.error
               for c in cols)
