"""The servo's dead band, identified from holds, and the motor model it completes (feedforward compensation).

HRP-2's motor drivers ignore current commands below a threshold (public figure: about +/-0.4 A), so the servo
produces no torque until its error ``q_des - q`` exceeds a band ``d`` [rad] on either side of the linear
prediction. At rest, where the velocity terms vanish, the paper's model then misses a step::

    dq_err = k_tau tau + d sign(tau)            (at rest: the servo holds the load tau)

The eq. 10 feedforward without ``d`` leaves the position feedback to supply it: the joint drifts until
``K6 e_q = d``, i.e. a static error ``d / K6`` (K6 = 0.1: 10 d). :func:`rest_dead_band` measures ``d`` from the
samples at rest of an identification log (the collection plan's holds, where the operator pushes the torque
through zero): half the jump of the rest residual ``dq_err - k_tau tau`` between positive and negative
torques. Coulomb friction does not enter at rest, which separates the two (the workbench's held-out ranking,
dominated by the sweeps, confuses them: docs/control.md).

:func:`with_dead_band` puts ``d`` into a motor model as its ``deadzone`` extra term (``damping_share = 0``,
``phi = clip(u / band, -1, 1)`` of the model's predicted command ``u``: the sign of ``tau`` at rest, where ``d``
was measured), replacing the one the workbench fitted if any. The controller's feedforward evaluates it on-line
with ``tau = tau*`` (control/torque.py): it adds ``d`` in the direction of the command it already sends, the
classic dead-zone inverse, smoothed over ``band``.

``python -m servotau.identification.deadband LOG MOTORS.toml OUT.toml`` writes MOTORS with the measured dead bands.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from servotau.errors import IdentificationError

DQ_REST = 0.005  # [rad/s] |dq| below this is at rest
TAU_MIN = 1.0  # [N m] |tau| above this on each side of the reversal (the torque estimate's noise is ~0.1 N m)
MIN_SAMPLES = 200  # at rest on each side of the reversal
BAND = 3e-5  # [rad] of the predicted command u over which the compensation changes sign (3 % of a 1 mrad band)


@dataclass(frozen=True)
class DeadBand:
    """Dead band of one joint from the samples at rest."""

    d: float  # [rad] half the jump of the rest residual at the torque reversal
    offset: float  # [rad] mean of the two sides (0 for a symmetric dead band; an encoder offset otherwise)
    n_positive: int  # samples at rest with tau > TAU_MIN
    n_negative: int  # samples at rest with tau < -TAU_MIN
    spread: float  # [rad] median absolute deviation of the residual on both sides (its noise)


def rest_dead_band(dq_err: np.ndarray, tau: np.ndarray, dq: np.ndarray, k_tau: float, *, dq_rest: float = DQ_REST,
                   tau_min: float = TAU_MIN, min_samples: int = MIN_SAMPLES) -> DeadBand:
    """Dead band [rad] from the samples at rest (``|dq| < dq_rest``) with ``|tau| > tau_min`` on both sides.

    Args:
        dq_err: ``q_des - q`` [rad], aligned with ``tau`` as for the motor fit.
        tau: Estimated joint torque [N m].
        dq: Estimated joint velocity [rad/s].
        k_tau: [rad/(N m)] the model's torque gain (the rest residual is ``dq_err - k_tau tau``).

    Raises:
        IdentificationError: Fewer than ``min_samples`` at rest on either side of the torque reversal (the
            log has no hold where the torque changes sign: push the limb both ways while it holds).
    """
    dq_err, tau, dq = (np.asarray(x, dtype=float) for x in (dq_err, tau, dq))
    if not (dq_err.shape == tau.shape == dq.shape and dq_err.ndim == 1):
        raise IdentificationError(f"dq_err, tau, dq: shapes {dq_err.shape}, {tau.shape}, {dq.shape}: expected "
                                  "equal 1-D shapes")
    rest = np.isfinite(dq_err) & np.isfinite(tau) & (np.abs(dq) < dq_rest)
    pos, neg = rest & (tau > tau_min), rest & (tau < -tau_min)
    n_pos, n_neg = int(pos.sum()), int(neg.sum())
    if min(n_pos, n_neg) < min_samples:
        raise IdentificationError(f"{n_pos} samples at rest with tau > {tau_min} N m and {n_neg} with tau < "
                                  f"-{tau_min} N m: expected >= {min_samples} on each side (hold the joint while "
                                  "its torque is pushed through zero)")
    r = dq_err - k_tau * tau
    hi, lo = float(np.median(r[pos])), float(np.median(r[neg]))
    spread = float(np.median(np.abs(np.concatenate([r[pos] - hi, r[neg] - lo]))))
    return DeadBand(d=max(0.0, (hi - lo) / 2.0), offset=(hi + lo) / 2.0, n_positive=n_pos, n_negative=n_neg,
                    spread=spread)


def with_dead_band(model, d: float, band: float = BAND, provenance: str = ""):
    """``model`` (a :class:`~servotau.identification.MotorModel`) with its ``deadzone`` extra term replaced by the
    dead band ``d`` [rad] (shape ``band``, ``damping_share = 0``), first among the extra terms."""
    from servotau.actuator import EffectTerm

    extra = {"deadzone": EffectTerm(float(d), {"band": float(band), "damping_share": 0.0})}
    extra.update({k: v for k, v in model.extra.items() if k != "deadzone"})
    return replace(model, extra=extra, provenance=provenance or model.provenance)


def dead_bands(aligned, models: Mapping) -> dict[str, DeadBand]:
    """:func:`rest_dead_band` of every joint of ``aligned`` (the data layer's
    :class:`~servotau.identification.data.AlignedLog`) with the ``k_tau`` of its model in ``models``."""
    return {joint: rest_dead_band(s.dq_err, s.tau, s.dq, models[joint].k_tau) for joint, s in aligned.samples.items()}


def with_dead_bands(params, aligned, source: str):
    """``params`` (:class:`~servotau.identification.MotorParameters`) with each joint's ``deadzone`` term measured
    on the holds of ``aligned`` (:func:`dead_bands`, :func:`with_dead_band`); and the dead bands."""
    from servotau.actuator import MotorParameters

    bands = dead_bands(aligned, params.models)
    models = {joint: with_dead_band(params[joint], db.d, provenance=f"{params[joint].provenance}; deadzone: "
                                    f"identification/deadband.py on the holds of {source}")
              for joint, db in bands.items()}
    return MotorParameters(models), bands


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m servotau.identification.deadband",
                                description="Measure each joint's dead band on the holds of an identification log "
                                            "and write the motor file with it as the deadzone term.")
    p.add_argument("log", help="identification log (servotau identify collect)")
    p.add_argument("motors", help="motor-parameter file to complete (its k_tau gives the rest residual)")
    p.add_argument("out", help="motor-parameter file to write")
    args = p.parse_args(argv)
    from servotau.actuator import MotorParameters
    from servotau.identification.data import load_aligned
    from servotau.identification.plan import load_plan

    base = MotorParameters.load_toml(args.motors)
    _, settings = load_plan()
    aligned = load_aligned(args.log, list(base.models), settings)
    params, bands = with_dead_bands(base, aligned, args.log)
    for joint, db in bands.items():
        print(f"{joint}: d = {1e3 * db.d:.3f} mrad (rest samples +{db.n_positive}/-{db.n_negative}, spread "
              f"{1e3 * db.spread:.3f} mrad, offset {1e3 * db.offset:+.3f} mrad)")
    params.save_toml(args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
