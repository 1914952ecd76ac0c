"""The identification plan file (``config/identification.toml``): what to collect and how to fit.

Collection timeline, in robot time from the first frame (the *timing contract* that a simulated
operator's scripted pushes follow, see ``config/scenarios/identification.toml``)::

    [0, settle)                          settle: hold still (F/T offsets and gyro bias calibration)
    sweeps, one per joint                q_des = q0 + (a0 + a t) sin(2 pi f t), then 1 s back to q0
    [.., holds_start)                    wait: hold still until the hold phase (if the sweeps end early)
    hold i, i = 0, 1, ...                [holds_start + i (move + hold), + move): move to configuration i
                                         [.. + move, .. + move + hold): hold while the operator pushes

``holds_start = 0`` starts the holds right after the sweeps (a real robot: a person pushes when
prompted, timing does not matter). Every phase lasts a whole number of ticks (durations are rounded
to the period as :class:`~servotau.identification.collect.Collector` does).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

from servotau.actuator.loss import LOSS_KINDS, Loss
from servotau.config import Section, check_settings, load_dataclass, load_toml, read_setting, setting
from servotau.errors import IdentificationError

from .collect import HoldPlan, SweepPlan
from .two_stage import DQ_STATIC

DEFAULT_PLAN = "identification.toml"  # under config/
SWEEP_RETURN = 1.0  # [s] the Collector's move back to q0 after each sweep
PHASES = ("settle", "sweep", "wait", "move", "hold")
"""Phase names; the log column ``ident/phase`` holds the index in this tuple."""


def ticks(seconds: float, period: float) -> int:
    """Ticks of a phase of ``seconds`` [s], rounded as the Collector does."""
    return int(round(seconds / period))


@dataclass(frozen=True)
class LossKeys:
    """The ``loss`` and ``w`` keys of the ``[fit]`` table: the loss of the fit written to the motor file."""

    loss: str = setting("asymmetric", choices=LOSS_KINDS)  # eq. 8 "asymmetric" or eq. 7 "least_squares"
    w: float = setting(100.0, min=1.0, strict_min=True)  # over-estimation weight of "asymmetric" (the paper's)

    def to_loss(self) -> Loss:
        return Loss.asymmetric(self.w) if self.loss == "asymmetric" else Loss.least_squares()

    @classmethod
    def read(cls, s: Section) -> Loss:
        """The loss of ``s``'s ``loss`` and ``w`` keys (``w`` only with the asymmetric loss)."""
        kind = read_setting(cls, "loss", s)
        if kind == "asymmetric":
            return Loss.asymmetric(read_setting(cls, "w", s))
        if "w" in s:
            raise s.error("w", s.data["w"], f'no w with loss = "{kind}"')
        return Loss.least_squares()


@dataclass(frozen=True)
class FitSettings:
    """How ``servotau identify fit`` turns a log into motor parameters (``[fit]`` table)."""

    loss: Loss = field(default_factory=lambda: LossKeys().to_loss())  # the keys `loss`, `w` (:class:`LossKeys`)
    coulomb: bool = setting(False)  # also fit k_c sign(dq) in the written fit (the paper drops it)
    two_stage: bool = setting(False)  # write the two-stage fit (section 3.3.1) instead of the joint fit
    dq_static: float = setting(DQ_STATIC, unit="rad/s", min=0.0, strict_min=True)  # static threshold (two-stage)
    downsample: int = setting(10, min=1)  # keep every n-th valid sample (paper: 1 kHz data downsampled)
    holdout_block: float = setting(1.0, unit="s", min=0.0, strict_min=True)  # blocks of the held-out split
    holdout_every: int = setting(3, min=2)  # every n-th block is held out (not fitted, used for the metrics)
    tau_shift: int = setting(1, unit="ticks", min=0, max=10)
    """dq_err[k] pairs with tau[k + tau_shift] (see :func:`~servotau.identification.data.load_aligned`)."""

    def __post_init__(self) -> None:
        check_settings(self, IdentificationError)

    @classmethod
    def from_section(cls, s: Section) -> FitSettings:
        s.check_keys([f.name for f in fields(cls)] + ["w"])
        return load_dataclass(cls, s, ignore=("w",), loss=LossKeys.read(s))


@dataclass(frozen=True)
class CollectionPlan:
    """The whole collection: settle, one sweep per joint, wait, holds (``[collect]`` table)."""

    sweeps: tuple[SweepPlan, ...]
    holds: HoldPlan = field(default_factory=HoldPlan)
    settle: float = setting(2.0, unit="s", min=0.0)
    holds_start: float = setting(0.0, unit="s", min=0.0)
    """Robot time (from the first frame) of the first hold's move; 0: right after the sweeps."""
    source: str = "<code>"  # file the plan was read from (error messages)

    def __post_init__(self) -> None:
        object.__setattr__(self, "sweeps", tuple(self.sweeps))
        check_settings(self, lambda msg: IdentificationError(f"{self.source}: {msg}"))
        names = [s.joint for s in self.sweeps]
        if len(set(names)) != len(names):
            raise IdentificationError(f"{self.source}: swept joints {names}: expected each joint once")
        if self.holds_start > 0 and self.sweeps_end > self.holds_start + 1e-9:
            raise IdentificationError(
                f"{self.source}: the settle phase and the sweeps end at {self.sweeps_end:g} s, after "
                f"holds_start = {self.holds_start:g} s: expected holds_start >= {self.sweeps_end:g} s (or 0), or "
                "fewer/shorter sweeps (the scenario's pushes are timed on holds_start)"
            )

    @property
    def joints(self) -> tuple[str, ...]:
        """The swept joints, in order."""
        return tuple(s.joint for s in self.sweeps)

    @property
    def sweeps_end(self) -> float:
        """[s] end of the last sweep's return move (nominal, before rounding to ticks)."""
        return self.settle + sum(s.duration + SWEEP_RETURN for s in self.sweeps)

    @property
    def hold_phase_start(self) -> float:
        """[s] start of the first hold's move."""
        return self.holds_start if self.holds_start > 0 else self.sweeps_end

    @property
    def duration(self) -> float:
        """[s] total robot time of the collection."""
        return self.hold_phase_start + len(self.holds.configurations) * (self.holds.move + self.holds.hold)

    def hold_windows(self) -> list[tuple[float, float]]:
        """``(start, end)`` [s] of each hold (the joints still, the operator pushing), after its move."""
        h, t0 = self.holds, self.hold_phase_start
        return [(t0 + i * (h.move + h.hold) + h.move, t0 + (i + 1) * (h.move + h.hold))
                for i in range(len(h.configurations))]

    def with_joints(self, joints: Sequence[str], defaults: SweepPlan | None = None) -> CollectionPlan:
        """The plan sweeping ``joints`` (in that order): their own settings if the plan has them, else
        ``defaults`` (else the first sweep's settings)."""
        own = {s.joint: s for s in self.sweeps}
        base = defaults or (self.sweeps[0] if self.sweeps else SweepPlan(joint=""))
        sweeps = [own.get(j) or replace(base, joint=j) for j in joints]
        return replace(self, sweeps=tuple(sweeps))

    def to_dict(self) -> dict:
        """JSON-ready description (stored in the log's metadata)."""
        return {
            "settle": self.settle,
            "holds_start": self.holds_start,
            "sweeps": [asdict(s) for s in self.sweeps],
            "holds": {"move": self.holds.move, "hold": self.holds.hold,
                      "configurations": [dict(c) for c in self.holds.configurations]},
            "source": self.source,
        }


def load_plan(path: str | Path = DEFAULT_PLAN) -> tuple[CollectionPlan, FitSettings]:
    """Read a plan file (relative paths also under config/).

    Raises:
        ConfigError: Naming the file, the field and the expected value.
        IdentificationError: Inconsistent timing (sweeps ending after ``holds_start``).
    """
    root = load_toml(path)
    root.check_keys(["collect", "fit"])
    c = root.section("collect")
    c.check_keys(["joints", "settle", "holds_start", "sweep", "hold"])
    joints = c.data.get("joints")
    if not isinstance(joints, list) or not all(isinstance(j, str) and j for j in joints):
        raise c.error("joints", joints if joints is not None else "missing", "a list of joint names to sweep")
    sweep = c.section("sweep", {})
    defaults = load_dataclass(SweepPlan, sweep, ignore=("joints",), joint="")
    per_joint = sweep.section("joints", {})
    for j in per_joint.keys():
        if j not in joints:
            raise per_joint.error(j, "{...}", f"a table for a swept joint, one of {joints}")
    sweeps = [load_dataclass(SweepPlan, per_joint.section(j), base=defaults, joint=j) if j in per_joint
              else replace(defaults, joint=j) for j in joints]
    h = c.section("hold", {})
    h.check_keys(["move", "hold", "configurations"])
    configs = h.data.get("configurations", [])
    if not isinstance(configs, list) or not all(isinstance(x, dict) for x in configs):
        raise h.error("configurations", configs, "an array of tables [[collect.hold.configurations]]")
    checked = []
    for i, cfg in enumerate(configs):
        sec = Section(cfg, h.file, f"{h.prefix}.configurations[{i}]")
        checked.append({k: sec.float(k, unit="rad") for k in sec.keys()})
    holds = load_dataclass(HoldPlan, h, ignore=("configurations",), configurations=checked)
    timing = {key: read_setting(CollectionPlan, key, c) for key in ("settle", "holds_start")}
    plan = CollectionPlan(sweeps=tuple(sweeps), holds=holds, source=root.file, **timing)  # IdentificationError
    return plan, FitSettings.from_section(root.section("fit", {}))


def check_joints(joints: Sequence[str], known: Sequence[str], what: str) -> list[str]:
    """``joints`` if every name is in ``known``, else an error naming ``what`` and the expected names."""
    joints = list(joints)
    if not joints:
        raise IdentificationError(f"{what}: no joint given: expected names among {list(known)}")
    for j in joints:
        if j not in known:
            raise IdentificationError(f'{what}: joint "{j}" is unknown: expected one of {list(known)}')
    if len(set(joints)) != len(joints):
        raise IdentificationError(f"{what}: {joints} repeats a joint: expected each joint once")
    return joints


def parse_joints(text: str | None) -> list[str] | None:
    """``"A,B, C"`` -> ``["A", "B", "C"]`` (None stays None)."""
    if text is None:
        return None
    return [j.strip() for j in text.split(",") if j.strip()]
