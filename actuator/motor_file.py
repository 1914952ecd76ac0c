"""The motor-parameter file: motor models by joint, in TOML (e.g. ``config/motors/<robot>.toml``).

File format (``version = 1``)::

    version = 1

    [joints.RLEG_JOINT3]
    k_tau = 5.1e-05            # [rad/(N m)], > 0
    k_v = 0.006561             # [rad/(rad/s)], >= 0
    k_c = 0.0001               # [rad], >= 0, optional
    loss = "asymmetric"        # or "least_squares" (then no w)
    w = 10.0                   # over-estimation weight, > 1
    provenance = "runs/ident_2025-01-01.parquet; 2025-01-01; backend=mujoco"

    [joints.RLEG_JOINT3.metrics]   # optional
    rms = 0.00012              # [rad], >= 0
    overestimation_rate = 0.04 # in [0, 1]
    n_samples = 20000

    [joints.RLEG_JOINT3.extra.deadzone]   # optional, any number of terms
    coefficient = 0.001
    shape = { e_deadzone = 0.003 }

A model of another target (``servotau model add ... --save`` on a friction or torque table) says what it
predicts and in which unit ``U``; ``k_tau`` and ``k_c`` are then optional, ``offset`` is a constant term, and
the signs of ``k_tau`` and ``k_v`` are free (they are checked only for a servo error)::

    [joints.joint]
    target = "torque"          # optional: "servo error" (default, q_des - q), "torque", or a column name
    unit = "N m"               # optional: the target's unit U (default "rad")
    k_v = 2.98                 # [U/(rad/s)]
    k_c = 1.49                 # [U], optional
    offset = 0.2               # [U], optional: a constant term
    loss = "least_squares"
    provenance = "friction.csv; servotau model add; least squares; tau: no torque"

A key left out is a term not in the model (never 0). The controller and the torque estimator read a model
only through :meth:`MotorParameters.servo_model`, which refuses one without ``k_tau``, with an ``offset``
or of another target, naming the file, the joint and the key.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from servotau.config import Section, load_toml
from servotau.errors import ConfigError, IdentificationError

from .loss import LOSS_KINDS, Loss
from .model import SERVO_ERROR, SERVO_UNIT, EffectTerm, FitMetrics, MotorModel
from .toml_writer import dumps as toml_dumps

FORMAT_VERSION = 1


@dataclass(frozen=True)
class MotorParameters(Mapping[str, MotorModel]):
    """Motor models by joint name, saved to and loaded from TOML; ``source``: the file read (for errors)."""

    models: Mapping[str, MotorModel]
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        for name, m in self.models.items():
            if not isinstance(name, str) or not name or not isinstance(m, MotorModel):
                raise IdentificationError(f"joint {name!r}: expected a MotorModel under a non-empty joint name")
        object.__setattr__(self, "models", dict(self.models))

    def __getitem__(self, joint: str) -> MotorModel:
        if joint not in self.models:
            raise IdentificationError(f"joint '{joint}' has no motor model: expected one of {list(self.models)}")
        return self.models[joint]

    def servo_model(self, joint: str) -> MotorModel:
        """The model of ``joint`` for the controller or the torque estimator: a servo-error model with
        ``k_tau`` and no offset (:meth:`MotorModel.servo_issue`).

        Raises:
            ConfigError: ``<file>: field 'joints.<joint>.<key>' ...: expected ...``.
        """
        m = self[joint]
        issue = m.servo_issue()
        if issue is not None:
            raise ConfigError(f"{self.source or '<motor parameters>'}: field 'joints.{joint}.{issue[0]}' {issue[1]}")
        return m

    def __contains__(self, joint: object) -> bool:
        return joint in self.models  # Mapping's default would turn the clear error above into a crash

    def __iter__(self) -> Iterator[str]:
        return iter(self.models)

    def __len__(self) -> int:
        return len(self.models)

    def save_toml(self, path: str | Path, notes: Sequence[str] = ()) -> Path:
        """Write the file (format in the module docstring), ``notes`` as comment lines at its top; return its
        path."""
        header = [*notes, *_FORMAT_LINES[:2]]
        if any(m.servo_issue() is not None for m in self.models.values()):  # a model for another use
            header.append(_FORMAT_LINES[2])
        joints = {}
        for joint, m in self.models.items():
            table: dict = {} if m.is_servo_error else {"target": m.target, "unit": m.unit}
            optional = {"k_tau": m.k_tau, "k_v": m.k_v, "k_c": m.k_c, "offset": m.offset, "loss": m.loss.kind,
                        "w": m.loss.w, "provenance": m.provenance}
            table.update({k: v for k, v in optional.items() if v is not None})
            if m.metrics is not None:
                table["metrics"] = {"rms": m.metrics.rms, "overestimation_rate": m.metrics.overestimation_rate,
                                    "n_samples": m.metrics.n_samples}
            if m.extra:
                table["extra"] = {name: {"coefficient": term.coefficient, "shape": dict(term.shape)}
                                  for name, term in m.extra.items()}
            joints[joint] = table
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(toml_dumps({"version": FORMAT_VERSION, "joints": joints}, header), encoding="utf-8")
        return p

    @staticmethod
    def notes_of(path: str | Path) -> list[str]:
        """The comment lines at the top of the motor file ``path`` (its provenance, a user's remarks) but the
        format's own, which :meth:`save_toml` writes: the ``notes`` to keep when the file is written again."""
        out = []
        for line in Path(path).read_text(encoding="utf-8").splitlines():
            if not line.startswith("#"):
                break
            text = line[2:].rstrip() if line.startswith("# ") else line[1:].rstrip()
            if text.strip() and text not in _FORMAT_LINES:
                out.append(text)
        return out

    @classmethod
    def load_toml(cls, path: str | Path) -> MotorParameters:
        """Read and validate a file.

        Raises:
            ConfigError: Naming the file, the field and the expected value.
        """
        root = load_toml(path)
        root.check_keys(["version", "joints"])
        version = root.int("version")
        if version != FORMAT_VERSION:
            raise root.error("version", version, f"{FORMAT_VERSION}")
        joints = root.section("joints")
        if not joints.keys():
            raise root.error("joints", {}, "at least one joint table")
        return cls({name: _load_model(joints.section(name)) for name in joints.keys()}, source=root.file)


def _shape_minimums(name: str) -> dict[str, float]:
    """The lower bound of each shape parameter of effect ``name`` (:meth:`~.registry.Effect.shape_minimums`); none
    for an effect not registered (a plugin's, loaded later)."""
    from .registry import effect_names, get_effect

    return get_effect(name).shape_minimums() if name in effect_names() else {}


_FORMAT_LINES = (
    "servotau motor parameters: dq_err = k_tau*tau + k_v*dq [+ k_c*sign(dq)] [+ extra terms]",
    "Units: k_tau [rad/(N m)], k_v [rad/(rad/s)], k_c [rad], rms [rad].",
    "A joint with 'target' and 'unit' U predicts that instead: k_tau [U/(N m)], k_v [U/(rad/s)], k_c, offset and rms "
    "[U]; a key left out is a term not in the model.",
)  # the header lines save_toml writes after the notes


def _load_model(sec: Section) -> MotorModel:
    sec.check_keys(["target", "unit", "k_tau", "k_v", "k_c", "offset", "loss", "w", "provenance", "metrics",
                    "extra"])
    target, unit = sec.str("target", SERVO_ERROR), sec.str("unit", SERVO_UNIT)
    for key, v in (("target", target), ("unit", unit)):
        if not v.strip():
            raise sec.error(key, v, "a non-empty string")
    servo = target == SERVO_ERROR and unit == SERVO_UNIT
    low = 0.0 if servo else None  # the paper's signs hold for a servo error only
    kind = sec.str("loss", choices=LOSS_KINDS)
    if kind == "asymmetric":
        loss = Loss(kind, sec.float("w", min=1.0, strict_min=True))
    elif "w" in sec:
        raise sec.error("w", sec.data["w"], 'no w with loss = "least_squares"')
    else:
        loss = Loss(kind)
    provenance = sec.str("provenance")
    if not provenance:
        raise sec.error("provenance", provenance, "a non-empty string (log file, date, backend)")
    metrics = None
    if "metrics" in sec:
        ms = sec.section("metrics")
        ms.check_keys(["rms", "overestimation_rate", "n_samples"])
        metrics = FitMetrics(
            ms.float("rms", min=0.0, unit=unit),
            ms.float("overestimation_rate", min=0.0, max=1.0),
            ms.int("n_samples", min=0),
        )
    extra = {}
    for name in sec.section("extra", {}).keys():
        es = sec.section("extra").section(name)
        es.check_keys(["coefficient", "shape"])
        shape = es.section("shape", {})
        least = _shape_minimums(name)
        extra[name] = EffectTerm(es.float("coefficient"), {k: shape.float(k, min=least.get(k)) for k in shape.keys()})
    return MotorModel(
        k_tau=sec.float("k_tau", min=low, strict_min=servo, unit=f"{unit}/(N m)") if "k_tau" in sec else None,
        k_v=sec.float("k_v", min=low, unit=f"{unit}/(rad/s)"),
        k_c=sec.float("k_c", min=0.0, unit=unit) if "k_c" in sec else None,
        extra=extra,
        loss=loss,
        provenance=provenance,
        metrics=metrics,
        offset=sec.float("offset", unit=unit) if "offset" in sec else None,
        target=target,
        unit=unit,
    )
