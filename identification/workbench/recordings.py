"""Several recordings as one dataset: one segment per recording, so held-out means leave-one-recording-out.

Each recording is read and preprocessed on its own (:func:`~.data.load_dataset`); :func:`combine` joins them:
the signals they all have, end to end (time continued one sample period after the previous recording's
end), ``segment`` = the recording's index (0, 1, ...), the cross-validation's blocks. Each recording's runs
(:attr:`~servotau.actuator.signals.Signals.starts`: its first sample, and any gap inside it) stay runs of the
joined signals, so the effects' filters restart at every join and never read another recording's samples.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from servotau.actuator import Signals
from servotau.errors import IdentificationError

from .data import Dataset

__all__ = ["combine"]

DT_TOLERANCE = 0.01  # relative difference of sample periods accepted between recordings


def combine(datasets: Sequence[Dataset]) -> Dataset:
    """One :class:`Dataset` of ``datasets`` (each one segment); a single dataset is returned unchanged.

    Raises:
        IdentificationError: The recordings' roles or sample periods differ.
    """
    if len(datasets) == 1:
        return datasets[0]
    if not datasets:
        raise IdentificationError("no recording: expected at least one log")
    first = datasets[0]
    for d in datasets[1:]:
        if dict(d.roles) != dict(first.roles):
            raise IdentificationError(f"{d.source}: roles {dict(d.roles)} differ from {first.source}'s "
                                      f"{dict(first.roles)}: expected recordings of the same layout")
        if (d.dt is None) != (first.dt is None) or (
                d.dt is not None and abs(d.dt - first.dt) > DT_TOLERANCE * first.dt):
            raise IdentificationError(f"{d.source}: sample period {d.dt} s differs from {first.source}'s {first.dt} s: "
                                      "expected recordings at the same rate")
    names = [k for k in first.signals if all(k in d.signals for d in datasets)]
    cols = {}
    for k in names:
        parts = [np.asarray(d.signals[k], dtype=np.float64) for d in datasets]
        if k == "t":
            step = first.dt or 1.0
            out, end = [], None
            for p in parts:
                p = p - p[0] + (0.0 if end is None else end + step)
                out.append(p)
                end = p[-1]
            parts = out
        cols[k] = np.concatenate(parts)
    n = sum(d.n for d in datasets)
    segment = np.concatenate([np.full(d.n, float(i)) for i, d in enumerate(datasets)])
    offsets = np.cumsum([0] + [d.n for d in datasets[:-1]])
    starts = [o + k for o, d in zip(offsets, datasets, strict=True) for k in d.signals.starts]
    notes = [f"{len(datasets)} recordings, one segment each (held out: leave-one-recording-out): "
             + ", ".join(f"{i}={d.source}" for i, d in enumerate(datasets))]
    notes += [f"{d.source}: {x}" for d in datasets for x in d.notes]
    return Dataset(Signals(cols, first.dt, n, starts=starts), np.concatenate([d.target for d in datasets]), segment,
                   first.roles, " + ".join(d.source for d in datasets), first.joint, sum(d.n_dropped for d in datasets),
                   tuple(notes))
