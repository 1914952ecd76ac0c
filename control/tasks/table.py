"""Trajectory tables: a CSV or Parquet file with a time column ``t`` [s] and one column per joint [rad].

Columns are joint names of the robot; a column that is not (a typo, another robot's name) or a joint the task
lists in ``joints`` but the table lacks is a :class:`~servotau.errors.ConfigError` naming the file and the
column (with the closest joint name). Between rows the reference is a cubic spline with zero velocity at both
ends, so ``dq`` and ``ddq`` are continuous inside the table.
"""

from __future__ import annotations

import csv
import difflib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servotau.errors import ConfigError


@dataclass(frozen=True)
class Table:
    """The rows of a trajectory table: ``t`` (m,) [s] from 0, ``q`` (m, k) [rad] of ``joints``."""

    file: str
    joints: tuple[str, ...]
    t: np.ndarray
    q: np.ndarray


def _read(path: Path) -> tuple[list[str], np.ndarray]:
    if path.suffix.lower() == ".parquet":
        import pyarrow.parquet as pq

        table = pq.read_table(path)
        cols = table.column_names
        try:
            data = np.column_stack([table.column(c).to_numpy(zero_copy_only=False).astype(float) for c in cols])
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{path}: a column is not numeric ({exc}): expected numbers [s] and [rad]") from None
        return cols, data
    with open(path, newline="", encoding="utf-8") as f:
        rows = [r for r in csv.reader(f) if r and not r[0].lstrip().startswith("#")]
    if len(rows) < 3:
        raise ConfigError(f"{path}: {max(len(rows) - 1, 0)} data rows: expected a header and at least 2 rows")
    cols = [c.strip() for c in rows[0]]
    data = np.empty((len(rows) - 1, len(cols)))
    for i, r in enumerate(rows[1:], start=2):
        if len(r) != len(cols):
            raise ConfigError(f"{path}: line {i} has {len(r)} values: expected {len(cols)} (the header's columns)")
        try:
            data[i - 2] = [float(v) for v in r]
        except ValueError:
            raise ConfigError(f"{path}: line {i} = {r}: expected numbers [s] and [rad]") from None
    return cols, data


def load_table(path: str | Path, robot_joints: Sequence[str], expected: Sequence[str] = ()) -> Table:
    """Read a trajectory table; ``expected``: joints the table must have (the task's ``joints``).

    Raises:
        ConfigError: No ``t`` column, an unknown or missing joint column, times not increasing from >= 0,
            a value that is not a finite number.
    """
    path = Path(path)
    cols, data = _read(path)
    if "t" not in cols:
        raise ConfigError(f"{path}: columns {cols}: expected a time column 't' [s]")
    joints = [c for c in cols if c != "t"]
    if not joints:
        raise ConfigError(f"{path}: only a 't' column: expected joint columns named after the robot's joints")
    for c in joints:
        if c not in robot_joints:
            close = difflib.get_close_matches(c, robot_joints, n=1)
            hint = f' (did you mean "{close[0]}"?)' if close else ""
            raise ConfigError(f'{path}: column "{c}" is not a joint of the robot{hint}: expected "t" and joint '
                              f"names, e.g. {list(robot_joints[:3])}")
    for j in expected:
        if j not in joints:
            raise ConfigError(f'{path}: no column "{j}": expected a column for each joint of the task {list(expected)}'
                              f" (columns: {cols})")
    if len(set(cols)) != len(cols):
        raise ConfigError(f"{path}: columns {cols}: expected each column once")
    if not np.all(np.isfinite(data)):
        row = int(np.flatnonzero(~np.all(np.isfinite(data), axis=1))[0])
        raise ConfigError(f"{path}: row {row + 1} holds a value that is not a finite number: expected [s] and [rad]")
    t = data[:, cols.index("t")]
    if len(t) < 2 or t[0] < 0 or np.any(np.diff(t) <= 0):
        raise ConfigError(f"{path}: column 't' = {t[:4].tolist()}...: expected at least 2 times >= 0, increasing [s]")
    q = np.column_stack([data[:, cols.index(j)] for j in joints])
    return Table(str(path), tuple(joints), t - t[0], q)
