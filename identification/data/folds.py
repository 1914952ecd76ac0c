"""Held-out data: the paper pipeline's hold-out split and the workbench's blocked cross-validation folds.

Neighbouring samples of an actuator log are nearly equal (filtered velocity, slow dynamics), so every split
holds out contiguous blocks, never random samples. The two callers keep their own rules:

- :func:`holdout_split` (``servotau identify fit``): one split; blocks of ``block`` seconds of the log's time,
  every ``every``-th held out, no guard; then every ``downsample``-th valid sample of each set.
- :func:`blocked_folds` (the workbench): ``folds`` blocks, each predicted by a model fitted on the others; the
  blocks are the log's ``segment`` labels when it has at least two (consecutive segments grouped into at
  most ``folds`` blocks: with as many folds as segments, leave-one-segment-out, which is how several
  recordings are held out), else of equal sample count; a guard band of ``guard`` samples on each side is
  removed from training, and nothing is downsampled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from servotau.errors import IdentificationError

DEFAULT_FOLDS = 5
GUARD_S = 0.1  # [s]
MIN_SEGMENTS = 2  # segments that make the folds (two recordings: each held out, fitted on the other)


def time_blocks(t: np.ndarray, block: float) -> np.ndarray:
    """Index of the ``block``-second block of each sample, counted from ``t[0]``."""
    return np.floor((t - t[0]) / block).astype(np.int64)


def holdout_split(t: np.ndarray, valid: np.ndarray, block: float, every: int,
                  downsample: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Boolean masks ``(train, held_out)``: blocks of ``block`` seconds, every ``every``-th (the last of each
    group of ``every``) held out; of each set's ``valid`` samples, every ``downsample``-th is kept."""
    held = time_blocks(t, block) % every == every - 1
    train, test = np.zeros(len(t), bool), np.zeros(len(t), bool)
    for mask, out in ((valid & ~held, train), (valid & held, test)):
        idx = np.flatnonzero(mask)
        out[idx[::downsample]] = True
    return train, test


@dataclass(frozen=True, eq=False)
class Fold:
    """One held-out block: ``test`` indices and the boolean ``train`` mask (guard band removed)."""

    test: np.ndarray
    train: np.ndarray
    label: str


def blocked_folds(n: int, folds: int = DEFAULT_FOLDS, segment: np.ndarray | None = None, guard: int = 0) -> list[Fold]:
    """Contiguous held-out blocks: by ``segment`` label (consecutive labels grouped into at most ``folds``
    blocks) if given with at least 2 labels (two segments: each predicted by a model fitted on the other),
    else ``folds`` blocks of equal length."""
    if folds < 2:
        raise IdentificationError(f"folds = {folds}: expected at least 2 held-out blocks")
    bounds: list[tuple[int, int, str]] = []
    if segment is not None:
        change = np.flatnonzero(np.diff(segment) != 0) + 1
        starts = np.concatenate([[0], change])
        ends = np.concatenate([change, [n]])
        if len(starts) >= MIN_SEGMENTS:
            groups = np.array_split(np.arange(len(starts)), min(folds, len(starts)))
            for g in groups:
                a, b = int(starts[g[0]]), int(ends[g[-1]])
                labels = sorted({segment[a], segment[b - 1]})
                bounds.append((a, b, "segment " + "-".join(f"{v:g}" for v in labels)))
    if not bounds:
        edges = np.linspace(0, n, folds + 1).round().astype(int)
        bounds = [(int(a), int(b), f"block {i + 1}/{folds}") for i, (a, b) in enumerate(zip(edges[:-1], edges[1:],
                                                                                              strict=True))]
    out = []
    for a, b, label in bounds:
        train = np.ones(n, dtype=bool)
        train[max(0, a - guard) : min(n, b + guard)] = False
        if not train.any():
            raise IdentificationError(f"held-out {label}: no training samples left: expected more data or folds")
        out.append(Fold(np.arange(a, b), train, label))
    return out


def folds_of(ds, folds: int = DEFAULT_FOLDS, guard_s: float = GUARD_S) -> list[Fold]:
    """:func:`blocked_folds` of a workbench :class:`~servotau.identification.workbench.Dataset` (its samples,
    sampling period and ``segment`` labels), with a guard of ``guard_s`` seconds."""
    guard = int(round(guard_s / ds.dt)) if ds.dt else 0
    return blocked_folds(ds.n, folds, ds.segment, guard)
