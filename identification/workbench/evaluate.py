"""Model against measurement: error metrics, blocked cross-validation by segment, training and held-out.

Residuals of an actuator model are strongly autocorrelated (filtered velocity, slow dynamics), so a
sample-wise split or a classical p-value flatters any extra term. The workbench judges models only on
held-out *segments*: the log is cut into ``folds`` contiguous blocks (or grouped by its ``segment``
column); each block is predicted by the model fitted on the others, minus a guard band of ``guard``
seconds on each side of the block (the data layer's :func:`~servotau.identification.data.blocked_folds`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np

from servotau.actuator.loss import Loss

from ..data.folds import Fold, folds_of
from ..metrics import overestimation_rate, signed_excess
from .data import Dataset
from .model import FittedModel, ModelSpec, fit_spec, resolve_shapes

REPORT_W = 10.0  # over-estimation weight of the reported asymmetric loss when fitting by least squares

__all__ = ["REPORT_W", "Comparison", "Metrics", "asymmetric_mean", "compare", "cross_validate", "error_of", "metrics"]


@dataclass(frozen=True)
class Metrics:
    """Model against measurement on a set of samples.

    Attributes:
        fit_percent: ``100 (1 - |y - model| / |y - mean(y)|)`` (NRMSE fit; 100 is perfect, 0 is the mean).
        rms: RMS of the residual ``y - model`` [unit of the target].
        asymmetric_loss: Mean of eq. 8's penalty, over-estimation weighted ``w`` [unit^2].
        w: The weight used.
        overestimation_rate: Fraction of samples where the model over-estimates ``|y|``.
        error: The criterion of the loss: RMS for least squares, ``sqrt(asymmetric_loss)`` otherwise.
        n: Number of samples.
    """

    fit_percent: float
    rms: float
    asymmetric_loss: float
    w: float
    overestimation_rate: float
    error: float
    n: int

    def to_dict(self) -> dict:
        return asdict(self)


def asymmetric_mean(residual: np.ndarray, target: np.ndarray, w: float) -> float:
    """Mean of eq. 8's penalty for ``residual = target - model``."""
    z = signed_excess(target - residual, target)
    return float(np.mean(np.where(z > 0, w, 1.0) * residual * residual)) if residual.size else 0.0


def error_of(residual: np.ndarray, target: np.ndarray, loss: Loss) -> float:
    """``sqrt`` of the mean loss of ``residual = target - model``: the ranking criterion."""
    if loss.kind == "least_squares":
        return float(np.sqrt(np.mean(residual * residual))) if residual.size else 0.0
    return float(np.sqrt(asymmetric_mean(residual, target, loss.w)))


def metrics(target: np.ndarray, model: np.ndarray, loss: Loss) -> Metrics:
    """:class:`Metrics` of ``model`` against ``target``."""
    r = target - model
    w = loss.w if loss.w is not None else REPORT_W
    spread = float(np.linalg.norm(target - target.mean())) if target.size else 0.0
    fit = 100.0 * (1.0 - float(np.linalg.norm(r)) / spread) if spread > 0 else float("nan")
    return Metrics(
        fit_percent=fit,
        rms=float(np.sqrt(np.mean(r * r))),
        asymmetric_loss=asymmetric_mean(r, target, w),
        w=float(w),
        overestimation_rate=overestimation_rate(model, target),
        error=error_of(r, target, loss),
        n=int(target.size),
    )


@dataclass(frozen=True, eq=False)
class Comparison:
    """A model against the measurement: fitted on everything (training) and cross-validated (held-out).

    Attributes:
        model: The model fitted on all samples (or the given model, if it was not refitted).
        target: The measurement.
        train: Metrics of ``model`` on all samples.
        heldout: Metrics of the cross-validated predictions (None for a given model: nothing held out).
        prediction: ``model`` on all samples.
        heldout_prediction: Each block predicted by the model fitted without it (None for a given model).
        fold_errors: Held-out error per block.
    """

    model: FittedModel
    target: np.ndarray
    train: Metrics
    heldout: Metrics | None
    prediction: np.ndarray
    heldout_prediction: np.ndarray | None
    fold_errors: Mapping[str, float]

    @property
    def residual(self) -> np.ndarray:
        """Held-out residual if available, else the training residual (target - model)."""
        return self.target - (self.heldout_prediction if self.heldout_prediction is not None else self.prediction)


def cross_validate(
    ds: Dataset, spec: ModelSpec, loss: Loss, folds: list[Fold], cache: dict | None = None
) -> np.ndarray:
    """Held-out prediction of every sample by ``spec`` fitted on the other blocks."""
    pred = np.full(ds.n, np.nan)
    for f in folds:
        m = fit_spec(ds.signals, ds.target, spec, loss, rows=f.train, cache=cache, drop_unexcited=True)
        pred[f.test] = m.predict(ds.signals)[f.test]
    return pred


def compare(
    ds: Dataset,
    spec: ModelSpec | FittedModel,
    loss: Loss | None = None,
    *,
    folds: list[Fold] | None = None,
    cache: dict | None = None,
) -> Comparison:
    """Fit ``spec`` (terms without a shape get the best of their grid) or take a fitted model as it is, and
    measure it against ``ds``."""
    if isinstance(spec, FittedModel):
        model = spec
        pred = model.predict(ds.signals)
        return Comparison(model, ds.target, metrics(ds.target, pred, loss or spec.loss), None, pred, None, {})
    loss = loss or Loss.least_squares()
    folds = folds or folds_of(ds)
    if any(t.shape is None for t in spec.terms):
        spec = resolve_shapes(ds.signals, ds.target, spec, loss, cache)
    model = fit_spec(ds.signals, ds.target, spec, loss, cache=cache)
    pred = model.predict(ds.signals)
    held = cross_validate(ds, spec, loss, folds, cache)
    per = {f.label: error_of(ds.target[f.test] - held[f.test], ds.target[f.test], loss) for f in folds}
    return Comparison(model, ds.target, metrics(ds.target, pred, loss), metrics(ds.target, held, loss), pred, held, per)
