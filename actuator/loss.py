"""The loss a motor model was fitted with: plain least squares (paper eq. 7) or the asymmetric penalty (eq. 8).

The motor file records it (``loss``, ``w``); the identification minimises it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from servotau.errors import IdentificationError

LOSS_KINDS = ("least_squares", "asymmetric")


MAX_WEIGHT = 1e6  # beyond, the weighted normal equations lose every digit of the under-estimating samples


def check_weight(w: object) -> float:
    """Return the asymmetric weight ``w`` as a float, or raise unless it is a number in (1, :data:`MAX_WEIGHT`]."""
    if isinstance(w, bool) or not isinstance(w, (int, float, np.floating, np.integer)) or not math.isfinite(w) \
            or w <= 1.0:
        raise IdentificationError(f"w = {w!r}: expected a finite number > 1 (over-estimation weight)")
    if w > MAX_WEIGHT:
        raise IdentificationError(f"w = {w!r}: expected at most {MAX_WEIGHT:g} (over-estimation weight)")
    return float(w)


@dataclass(frozen=True)
class Loss:
    """Which loss a fit minimises.

    Attributes:
        kind: ``"least_squares"`` or ``"asymmetric"``.
        w: Over-estimation weight (> 1) for ``"asymmetric"``, ``None`` for least squares.
    """

    kind: str = "least_squares"
    w: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in LOSS_KINDS:
            raise IdentificationError(f"loss kind = {self.kind!r}: expected one of {list(LOSS_KINDS)}")
        if self.kind == "asymmetric":
            object.__setattr__(self, "w", check_weight(self.w))
        elif self.w is not None:
            raise IdentificationError(f"w = {self.w!r}: expected None for a least-squares loss")

    @classmethod
    def least_squares(cls) -> Loss:
        return cls("least_squares")

    @classmethod
    def asymmetric(cls, w: float) -> Loss:
        return cls("asymmetric", w)

    def __str__(self) -> str:
        return self.kind if self.w is None else f"{self.kind}(w={self.w:g})"
