"""``viscous_power``: viscous friction growing as a power of the speed (a lubricant film, seals): ``|v|^delta``.

``phi = sgn(dq) |dq / V_REF|^delta`` (``V_REF`` = 1 rad/s: the coefficient is the friction at 1 rad/s [rad]).
The linear viscous part is the base model's ``k_v dq``, always fitted with it: the term holds only the curvature,
and the grid leaves out ``delta = 1``, where the column is ``k_v``'s. The grid is sub-linear only (``delta < 1``):
lubricated contacts grow slower than linearly with speed (full-film friction goes as about ``v^0.5``), while a
convex term would stand in for a Stribeck drop beyond the Stribeck grid (it did on the simulator's out-of-grid
Stribeck log). On-line: ``dq``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ..excitation import Excitation, both_directions, slow_and_fast
from ..friction_state import FRICTION_COEFFICIENT
from ..registry import Effect
from ..signals import Signals

ORDER = 32
V_REF = 1.0  # [rad/s] the speed at which the coefficient is the friction
DELTA = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8)  # exponents tried (1: the base model's k_v)
GRID = tuple({"delta": d} for d in DELTA)


def viscous_power(s: Signals, delta: float) -> np.ndarray:
    dq = s["dq"]
    return np.sign(dq) * np.abs(dq / V_REF) ** delta


def scalar(x: Mapping[str, float], delta: float) -> float:
    dq = x["dq"]
    return math.copysign(abs(dq / V_REF) ** delta, dq) if dq != 0.0 else 0.0


def needs(e: Excitation) -> str | None:
    """Several speeds (the exponent is the curvature of friction against speed), in both directions."""
    speeds = slow_and_fast(e)
    return f"{speeds} (the power of the speed needs several speeds)" if speeds else both_directions(e)


EFFECT = Effect(
    "viscous_power", viscous_power, GRID, ("dq",),
    signature="residual against velocity bends like |dq|^delta (odd): concave for delta < 1 (steep at low speed, "
    "flattening), with no step at dq = 0",
    family="velocity",
    description="viscous friction growing as a power of the speed (lubricant film, seals)",
    needs=needs,
    scalar=scalar,
    online_signals="dq",
    coefficient_range=FRICTION_COEFFICIENT,
    confusable=("coulomb", "stribeck"),
    experiments={
        "coulomb": "constant-velocity ramps at speeds spanning a decade or more (0.02 to 1 rad/s): the power-law "
        "friction keeps growing with speed as |v|^delta, Coulomb friction is flat (and steps at dq = 0)",
        "stribeck": "constant-velocity ramps at several slow speeds (0.01 to 0.3 rad/s): Stribeck friction falls "
        "from its breakaway level with speed, the power law only rises",
    },
    phi_unit="1",
)
