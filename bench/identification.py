"""Time the asymmetric fit (paper eq. 8): exact Newton method vs the OSQP QP of eq. 9.

Synthetic data from a known actuator with a dead zone and Coulomb friction
(servotau.identification.make_synthetic), model dq_err = k_tau tau + k_v dq + k_c sign(dq), w = 10.
Newton is timed at 1e3..1e6 samples (median of 3 runs), OSQP once per size up to --osqp-max
(default 1e5: OSQP needs ~1 s at 1e4, ~20 s at 1e5 and minutes at 1e6). Times include input validation.
Over-estimation rates of least squares and of the asymmetric fit (model dq_err = k_tau tau + k_v dq,
fitted on 1e4 samples) are measured on 1e5 held-out samples.

--json prints one JSON object; otherwise a table.
"""

import argparse
import json
import statistics
import time

import numpy as np

from servotau.identification import (
    fit_asymmetric,
    fit_least_squares,
    linear_regressors,
    make_synthetic,
    overestimation_rate,
)

W = 10.0  # [-] over-estimation weight
SIZES = {"1e3": 1_000, "1e4": 10_000, "1e5": 100_000, "1e6": 1_000_000}


def timed(fn, runs: int):
    """Median wall time [s] of ``runs`` calls and the last result."""
    times, result = [], None
    for _ in range(runs):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def run(osqp_max: int) -> dict:
    out: dict = {"w": W, "model": "k_tau*tau + k_v*dq + k_c*sign(dq)", "data": "synthetic dead zone + Coulomb"}
    for label, m in SIZES.items():
        d = make_synthetic(m, seed=m)
        a = linear_regressors(d.tau, d.dq, coulomb=True)
        t_newton, newton = timed(lambda a=a, d=d: fit_asymmetric(a, d.dq_err, W, solver="newton"), 3)
        out[f"asym_fit_s_newton_{label}"] = round(t_newton, 5)
        out[f"newton_iterations_{label}"] = newton.iterations
        if m <= osqp_max:
            t_osqp, qp = timed(lambda a=a, d=d: fit_asymmetric(a, d.dq_err, W, solver="osqp"), 1)
            out[f"asym_fit_s_osqp_{label}"] = round(t_osqp, 4)
            out[f"max_rel_coef_diff_{label}"] = float(np.max(np.abs(qp.x - newton.x) / np.abs(newton.x)))
        elif label in ("1e5", "1e6"):
            out[f"asym_fit_s_osqp_{label}"] = None
            out[f"max_rel_coef_diff_{label}"] = None
            out[f"note_osqp_{label}"] = f"skipped: above --osqp-max {osqp_max:g} (OSQP takes minutes at 1e6)"
    train, held = make_synthetic(10_000, seed=1), make_synthetic(100_000, seed=2)
    a_train, a_held = linear_regressors(train.tau, train.dq), linear_regressors(held.tau, held.dq)
    ls = fit_least_squares(a_train, train.dq_err)
    asym = fit_asymmetric(a_train, train.dq_err, W)
    out["overestimation_rate_ls"] = round(overestimation_rate(ls.predict(a_held), held.dq_err), 4)
    out["overestimation_rate_asym"] = round(overestimation_rate(asym.predict(a_held), held.dq_err), 4)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--osqp-max", type=float, default=1e5, help="largest size solved with OSQP (default 1e5)")
    args = parser.parse_args()
    result = run(int(args.osqp_max))
    if args.json:
        print(json.dumps(result))
        return
    print(f"asymmetric fit, w = {W:g}, {result['model']}, {result['data']}")
    print(f"{'samples':>8} {'newton [s]':>11} {'iter':>5} {'osqp [s]':>10} {'max rel diff':>13}")
    for label in SIZES:
        osqp_s = result.get(f"asym_fit_s_osqp_{label}")
        diff = result.get(f"max_rel_coef_diff_{label}")
        print(
            f"{label:>8} {result[f'asym_fit_s_newton_{label}']:>11.4f} {result[f'newton_iterations_{label}']:>5} "
            f"{'-' if osqp_s is None else f'{osqp_s:.3f}':>10} {'-' if diff is None else f'{diff:.1e}':>13}"
        )
    print(
        f"held-out over-estimation rate: least squares {result['overestimation_rate_ls']:.3f}, "
        f"asymmetric {result['overestimation_rate_asym']:.3f}"
    )


if __name__ == "__main__":
    main()
