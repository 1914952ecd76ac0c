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
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

from servotau.config import Section, load_toml
from servotau.errors import IdentificationError

from .loss import LOSS_KINDS, Loss
from .model import EffectTerm, FitMetrics, MotorModel
from .toml_writer import key as toml_key
from .toml_writer import value as toml_value

FORMAT_VERSION = 1


@dataclass(frozen=True)
class MotorParameters(Mapping[str, MotorModel]):
    """Motor models by joint name, saved to and loaded from TOML."""

    models: Mapping[str, MotorModel]

    def __post_init__(self) -> None:
        for name, m in self.models.items():
            if not isinstance(name, str) or not name or not isinstance(m, MotorModel):
                raise IdentificationError(f"joint {name!r}: expected a MotorModel under a non-empty joint name")
        object.__setattr__(self, "models", dict(self.models))

    def __getitem__(self, joint: str) -> MotorModel:
        if joint not in self.models:
            raise IdentificationError(f"joint '{joint}' has no motor model: expected one of {list(self.models)}")
        return self.models[joint]

    def __contains__(self, joint: object) -> bool:
        return joint in self.models  # Mapping's default would turn the clear error above into a crash

    def __iter__(self) -> Iterator[str]:
        return iter(self.models)

    def __len__(self) -> int:
        return len(self.models)

    def save_toml(self, path: str | Path) -> Path:
        """Write the file (format in the module docstring); return its path."""
        lines = [
            "# servotau motor parameters: dq_err = k_tau*tau + k_v*dq [+ k_c*sign(dq)] [+ extra terms]",
            "# Units: k_tau [rad/(N m)], k_v [rad/(rad/s)], k_c [rad], rms [rad].",
            f"version = {FORMAT_VERSION}",
        ]
        for joint, m in self.models.items():
            table = f"joints.{toml_key(joint)}"
            lines += ["", f"[{table}]", f"k_tau = {toml_value(m.k_tau)}", f"k_v = {toml_value(m.k_v)}"]
            if m.k_c is not None:
                lines.append(f"k_c = {toml_value(m.k_c)}")
            lines.append(f"loss = {toml_value(m.loss.kind)}")
            if m.loss.w is not None:
                lines.append(f"w = {toml_value(m.loss.w)}")
            lines.append(f"provenance = {toml_value(m.provenance)}")
            if m.metrics is not None:
                lines += [
                    "",
                    f"[{table}.metrics]",
                    f"rms = {toml_value(m.metrics.rms)}",
                    f"overestimation_rate = {toml_value(m.metrics.overestimation_rate)}",
                    f"n_samples = {toml_value(m.metrics.n_samples)}",
                ]
            for name, term in m.extra.items():
                lines += [
                    "",
                    f"[{table}.extra.{toml_key(name)}]",
                    f"coefficient = {toml_value(term.coefficient)}",
                    f"shape = {toml_value(dict(term.shape))}",
                ]
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("\n".join(lines) + "\n", encoding="utf-8")
        return p

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
        return cls({name: _load_model(joints.section(name)) for name in joints.keys()})


def _load_model(sec: Section) -> MotorModel:
    sec.check_keys(["k_tau", "k_v", "k_c", "loss", "w", "provenance", "metrics", "extra"])
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
            ms.float("rms", min=0.0, unit="rad"),
            ms.float("overestimation_rate", min=0.0, max=1.0),
            ms.int("n_samples", min=0),
        )
    extra = {}
    for name in sec.section("extra", {}).keys():
        es = sec.section("extra").section(name)
        es.check_keys(["coefficient", "shape"])
        shape = es.section("shape", {})
        extra[name] = EffectTerm(es.float("coefficient"), {k: shape.float(k) for k in shape.keys()})
    return MotorModel(
        k_tau=sec.float("k_tau", min=0.0, strict_min=True, unit="rad/(N m)"),
        k_v=sec.float("k_v", min=0.0, unit="rad/(rad/s)"),
        k_c=sec.float("k_c", min=0.0, unit="rad") if "k_c" in sec else None,
        extra=extra,
        loss=loss,
        provenance=provenance,
        metrics=metrics,
    )
