"""Asymmetric-penalty identification, paper eq. 8, solved exactly by a Newton (IRLS) method.

With ``z_i = sign(b_i) (a_i x - b_i)`` the over-estimation of ``|b_i|`` by the model (see
:mod:`~servotau.identification.metrics`; ``z_i = |a_i x|`` where ``b_i == 0``), eq. 8 minimises::

    f(x) = sum_i Phi(z_i),   Phi(z) = w z^2 if z > 0 else z^2,   w > 1

``f`` is convex, C^1 and piecewise quadratic. For a fixed "active set" S (the samples with z > 0),
``f`` equals the weighted least-squares cost ``sum_i c_i (a_i x - b_i)^2`` with ``c_i = w`` on S and 1
elsewhere, minimised by the normal equations ``A^T C A x = A^T C b``. The method alternates that solve
with updating S from the new residuals (a damped step if the cost did not decrease); when S no longer
changes, the gradient of ``f`` is zero and, ``f`` being convex, ``x`` is the exact global minimiser.
The QP of eq. 9 (:mod:`~servotau.identification.asymmetric_qp`) gives the same ``x``.
"""

from __future__ import annotations

import time

import numpy as np

from servotau.actuator.loss import Loss, check_weight
from servotau.errors import IdentificationError

from .asymmetric_qp import solve_osqp
from .linear_fit import LinearFit, make_fit
from .problem import Problem, prepare_problem
from .regressors import Regressors
from .validation import MAX_CONDITION, label

SOLVERS = ("newton", "osqp")


def asymmetric_cost(residual: np.ndarray, dq_err: np.ndarray, w: float) -> float:
    """Eq. 8 cost of residuals ``model - dq_err`` [rad]: over-estimation of |dq_err| weighs ``w``."""
    over = _over(residual, np.sign(dq_err))
    return float(np.sum(np.where(over, w, 1.0) * residual * residual))


def _over(residual: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Over-estimating samples: ``s * residual > 0``, and every sample with ``s == 0``."""
    return (s * residual > 0.0) | (s == 0.0)


def _weighted_solve(prob: Problem, c: np.ndarray) -> np.ndarray:
    ac = prob.a * c[:, None]
    return np.linalg.solve(ac.T @ prob.a, ac.T @ prob.b)


def solve_newton(prob: Problem, w: float, *, max_iter: int = 100) -> tuple[np.ndarray, dict]:
    """Minimise eq. 8 on a scaled :class:`Problem`; return scaled ``x`` and a report.

    Raises:
        IdentificationError: If the active set still changes after ``max_iter`` iterations.
    """
    a, b, s = prob.a, prob.b, prob.side
    tie = 1e-12 * max(1.0, float(np.max(np.abs(b))))  # residuals this small count as zero
    x = np.linalg.solve(prob.gram, a.T @ b)  # least-squares start
    r = a @ x - b
    over = _over(r, s)
    cost = float(np.sum(np.where(over, w, 1.0) * r * r))
    damped = 0
    for it in range(1, max_iter + 1):
        x_new = _weighted_solve(prob, np.where(over, w, 1.0))
        r_new = a @ x_new - b
        over_new = _over(r_new, s)
        if not np.any((over_new != over) & (np.abs(r_new) > tie)):
            return x_new, {"iterations": it, "damped_steps": damped, "n_over": int(over_new.sum())}
        cost_new = float(np.sum(np.where(over_new, w, 1.0) * r_new * r_new))
        step = 1.0
        while cost_new >= cost and step > 1e-12:  # damped Newton step along x_new - x
            step *= 0.5
            damped += 1
            x_try = x + step * (x_new - x)
            r_new = a @ x_try - b
            over_new = _over(r_new, s)
            cost_new = float(np.sum(np.where(over_new, w, 1.0) * r_new * r_new))
        if cost_new >= cost:  # no descent left: x is optimal to machine precision
            return x, {"iterations": it, "damped_steps": damped, "n_over": int(over.sum())}
        x = x + step * (x_new - x)
        over, cost = over_new, cost_new
    raise IdentificationError(
        f"asymmetric fit (newton): active set still changing after max_iter = {max_iter} iterations: "
        "expected convergence; raise max_iter or check the data"
    )


def fit_asymmetric(
    regressors: Regressors,
    dq_err: np.ndarray,
    w: float,
    *,
    offset: np.ndarray | None = None,
    solver: str = "newton",
    min_samples: int | None = None,
    max_condition: float = MAX_CONDITION,
    what: str | None = None,
    constant: tuple[str, ...] = (),
    **solver_options,
) -> LinearFit:
    """Fit ``A x + offset ~ dq_err`` with the asymmetric penalty of eq. 8.

    Args:
        regressors: Named columns of ``A`` (e.g. from :func:`linear_regressors`).
        dq_err: Position tracking error ``q_des - q`` [rad]; its sign decides what over-estimates.
        w: Over-estimation weight, > 1.
        offset: Known part of the model [rad] (e.g. ``k_tau * tau`` from a first stage), or None.
        solver: ``"newton"`` (exact, fast) or ``"osqp"`` (the QP of eq. 9; slow beyond 1e4 samples).
        min_samples: Fewest samples accepted (default 10 per coefficient).
        max_condition: Largest accepted condition number of the column-normalised ``A``.
        what: Name of the data set, prefixed to error messages.
        constant: Names of columns that may be constant (a fitted offset: eq. 8 stays convex with it).
        **solver_options: ``max_iter`` for Newton; ``eps``, ``max_iter``, ``time_limit`` for OSQP.

    Raises:
        IdentificationError: Bad data, ``w <= 1``, unknown solver, or the solver failed.
    """
    w = check_weight(w)
    if solver not in SOLVERS:
        raise IdentificationError(f"solver = {solver!r}: expected one of {list(SOLVERS)}")
    prob = prepare_problem(
        regressors,
        dq_err,
        offset=offset,
        min_samples=min_samples,
        max_condition=max_condition,
        what=label(what, f"asymmetric fit ({solver})"),
        constant=constant,
    )
    start = time.perf_counter()
    if solver == "newton":
        xs, info = solve_newton(prob, w, **solver_options)
        status = "solved"
    else:
        xs, info = solve_osqp(prob, w, **solver_options)
        status = str(info["status"])
    elapsed = time.perf_counter() - start
    return make_fit(
        regressors,
        prob.dq_err,
        prob.unscale(xs),
        Loss.asymmetric(w),
        prob.condition,
        solver,
        offset=prob.offset,
        iterations=int(info.pop("iterations")),
        solve_time_s=elapsed,
        status=status,
        info=info,
    )
