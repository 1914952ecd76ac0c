"""The servo's dead band measured on the holds of a servotau log: the log's side of
:mod:`servotau.actuator.effects.deadzone`.

The estimate itself (:func:`~servotau.actuator.effects.deadzone.rest_dead_band`: half the jump of the rest
residual ``dq_err - k_tau tau`` at the torque reversal) and the motor model's ``deadzone`` term it makes
(:func:`~servotau.actuator.effects.deadzone.with_dead_band`) are the effect's. Here: each joint's samples from
the data layer (:func:`~servotau.identification.data.load_aligned`) and a motor file completed with them.

``servotau model add LOG --joint J ... --save OUT.toml --dead-band holds`` saves a workbench model with its
dead band measured here, in one step; ``python -m servotau.identification.deadband LOG MOTORS.toml OUT.toml``
writes MOTORS with the measured dead bands of all its joints.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path

from servotau.actuator import MotorParameters
from servotau.actuator.effects.deadzone import DeadBand, rest_dead_band, with_dead_band

from .data import load_aligned
from .plan import FitSettings, load_plan


def dead_bands(aligned, models: Mapping) -> dict[str, DeadBand]:
    """:func:`~servotau.actuator.effects.deadzone.rest_dead_band` of every joint of ``aligned`` (the data layer's
    :class:`~servotau.identification.data.AlignedLog`) with the ``k_tau`` of its model in ``models``."""
    return {joint: rest_dead_band(s.dq_err, s.tau, s.dq, models[joint].k_tau) for joint, s in aligned.samples.items()}


def with_dead_bands(params: MotorParameters, aligned, source: str) -> tuple[MotorParameters, dict[str, DeadBand]]:
    """``params`` with each joint's ``deadzone`` term measured on the holds of ``aligned`` (:func:`dead_bands`,
    :func:`~servotau.actuator.effects.deadzone.with_dead_band`); and the dead bands."""
    bands = dead_bands(aligned, {j: params.servo_model(j) for j in aligned.samples})  # k_tau, else an error
    models = {joint: with_dead_band(params[joint], db.d, provenance=f"{params[joint].provenance}; deadzone: "
                                    f"identification/deadband.py on the holds of {source}")
              for joint, db in bands.items()}
    return MotorParameters(models), bands


def with_log_dead_bands(params: MotorParameters, log: str | Path, settings: FitSettings | None = None
                        ) -> tuple[MotorParameters, dict[str, DeadBand]]:
    """:func:`with_dead_bands` on the holds of the servotau log ``log`` (its joints aligned by
    :func:`~servotau.identification.data.load_aligned` with ``settings``, default the plan's ``[fit]``
    settings, as ``servotau identify fit``); the provenance names ``log`` as given."""
    if settings is None:
        _, settings = load_plan()
    aligned = load_aligned(log, list(params.models), settings)
    return with_dead_bands(params, aligned, str(log))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m servotau.identification.deadband",
                                description="Measure each joint's dead band on the holds of an identification log "
                                            "and write the motor file with it as the deadzone term.")
    p.add_argument("log", help="identification log (servotau identify collect)")
    p.add_argument("motors", help="motor-parameter file to complete (its k_tau gives the rest residual)")
    p.add_argument("out", help="motor-parameter file to write")
    args = p.parse_args(argv)
    params, bands = with_log_dead_bands(MotorParameters.load_toml(args.motors), args.log)
    for joint, db in bands.items():
        print(f"{joint}: d = {1e3 * db.d:.3f} mrad (rest samples +{db.n_positive}/-{db.n_negative}, spread "
              f"{1e3 * db.spread:.3f} mrad, offset {1e3 * db.offset:+.3f} mrad)")
    params.save_toml(args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
