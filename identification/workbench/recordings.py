"""Several recordings as one dataset: one segment per recording, so held-out means leave-one-recording-out.

Each recording is read and preprocessed on its own (:func:`~.data.load_dataset`); :func:`combine` joins them:
the signals they all have, end to end (time continued one sample period after the previous recording's
end), ``segment`` = the recording's index (0, 1, ...), the cross-validation's blocks. Each recording's runs
(:attr:`~servotau.actuator.signals.Signals.starts`: its first sample, and any gap inside it) stay runs of the
joined signals, so the effects' filters restart at every join and never read another recording's samples.

The joined :attr:`~.data.Dataset.preprocessing` says, per derived signal, what every recording did: its ``windows``
(per recording: first row, window, period) let :func:`~.checks.faster_derivative` differentiate each recording with
half its own window, as it would alone. Recordings whose windows differ get a note naming each; a signal derived
in some recordings and not in others (``source`` "mixed") gets a note, and the faster-derivative check does not
run on a mixed velocity (half of no window is no check).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from servotau.actuator import Signals
from servotau.errors import IdentificationError

from .data import Dataset, windows_text

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
            raise IdentificationError(f"{d.source}: sample period {_period(d.dt)} differs from {first.source}'s "
                                      f"{_period(first.dt)}: expected recordings at the same rate")
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
    prep = _preprocessing(datasets, offsets, notes)
    return Dataset(Signals(cols, first.dt, n, starts=starts), np.concatenate([d.target for d in datasets]), segment,
                   first.roles, " + ".join(d.source for d in datasets), first.joint, sum(d.n_dropped for d in datasets),
                   tuple(notes), prep)


def _preprocessing(datasets: Sequence[Dataset], offsets, notes: list[str]) -> dict[str, dict]:
    """The joined preprocessing (module doc): per signal, what the recordings share, and the ``windows`` of those
    filtered; a note (added to ``notes``) when their windows differ or only some derived the signal."""
    out: dict[str, dict] = {}
    for key in dict.fromkeys(k for d in datasets for k in d.preprocessing):
        infos = [d.preprocessing.get(key, {}) for d in datasets]
        if key == "q":  # the encoder's resolution: the coarsest recording's sets the rounding floor
            res = [float(i.get("resolution", 0.0)) for i in infos]
            out[key] = {"source": "log", "resolution": max(res)}
            if len(set(res)) > 1:
                notes.append("q: the recordings' encoder resolutions differ (" + ", ".join(
                    f"{i}: {r:.3g} rad" if r else f"{i}: not quantised" for i, r in enumerate(res))
                    + f"): the coarsest, {max(res):.3g} rad, sets the rounding floor")
            continue
        sources = [i.get("source", "not derived") for i in infos]
        if len(set(sources)) > 1:
            out[key] = {"source": "mixed", "sources": tuple(sources)}
            notes.append(f"{key}: the recordings differ: " + ", ".join(f"{i}: {s}" for i, s in enumerate(sources))
                         + (" (no faster-derivative check)" if key == "dq" else ""))
            continue
        out[key] = {k: v for k, v in infos[0].items() if all(i.get(k) == v for i in infos)}
        if "window" not in infos[0]:
            continue
        windows = [int(i["window"]) for i in infos]
        out[key]["windows"] = tuple((int(o), w, float(d.dt)) for o, w, d in zip(offsets, windows, datasets,
                                                                                 strict=True))
        out[key]["orders"] = tuple(int(i.get("order", 2)) for i in infos)
        if len(set(windows)) > 1:
            out[key]["window"] = windows_text(windows)
            notes.append(f"{key}: each recording filtered with its own window: {windows_text(windows)} samples "
                         f"(recordings {windows_text(list(range(len(datasets))))})")
    return out


def _period(dt: float | None) -> str:
    return "unknown (no time column)" if dt is None else f"{1e3 * dt:.6g} ms"
