"""Reading a log: tables (Parquet or CSV), servotau logs, and the role of each column.

Both identification paths read the project's Parquet logs; they keep their own readers:

- :func:`open_log` (``servotau identify fit``): a servotau log through :class:`~servotau.hal.log.LogReader`
  (Parquet, or the ``.parts`` folder of an interrupted recording), with its :class:`RobotInfo` and metadata.
- :func:`read_table` (the workbench): any Parquet or CSV table, its numeric columns as float arrays; the
  role of each column (target, command, position, torque, ...) from a mapping or a recognised layout
  (:func:`resolve_roles`; the layouts are described in :mod:`servotau.identification.workbench.data`).
"""

from __future__ import annotations

import csv
import logging
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from servotau.errors import HalError, IdentificationError

log = logging.getLogger(__name__)

ROLES = ("target", "command", "position", "torque", "velocity", "acceleration", "time", "segment")


def open_log(path: str | Path):
    """A :class:`~servotau.hal.log.LogReader` of the servotau log ``path``.

    Raises:
        IdentificationError: No such file (nor its ``.parts`` folder), or not a servotau Parquet log.
    """
    from servotau.hal.log import LogReader

    path = Path(path)
    if not path.exists() and not Path(str(path) + ".parts").exists():
        raise IdentificationError(f"{path}: no such log file: expected a Parquet log from `servotau identify collect`")
    try:
        return LogReader(path)
    except HalError as exc:
        raise IdentificationError(f"{path}: cannot read the log ({exc}): expected a servotau Parquet log") from exc
    except Exception as exc:  # pyarrow's errors for a file that is not Parquet
        raise IdentificationError(f"{path}: not a Parquet log ({type(exc).__name__}: {exc})") from exc


DELIMITERS = (",", ";", "\t")
"""CSV delimiters: the one that splits each of the first lines (quotes respected) into the same number of columns,
the most, separates them (a comma on a tie)."""
SNIFF_BYTES = 65536  # [bytes] read to check a CSV file is text and find its header line


def _csv_delimiter(p: Path) -> str:
    """The delimiter of the CSV file ``p`` (``DELIMITERS``, from its first lines; ``,`` for one column).

    Raises:
        IdentificationError: The file's start is not UTF-8 text (a binary file named .csv).
    """
    with p.open("rb") as f:
        head = f.read(SNIFF_BYTES)
    if head.startswith(b"PAR1"):
        raise IdentificationError(f"log file {p}: a Parquet file (it starts with PAR1) named like a CSV table: "
                                  "expected the suffix .parquet (rename the file)")
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if exc.start < len(head) - 3:  # not a multi-byte character cut at the end of the sniffed bytes
            raise IdentificationError(f"log file {p}: byte {exc.start} is not UTF-8 text (a binary file, or a "
                                      "Latin-1 or Windows export?): expected a CSV table in UTF-8 or a .parquet "
                                      "file") from None
        text = head[:exc.start].decode("utf-8")
    if "\x00" in text:
        raise IdentificationError(f"log file {p}: binary content (a NUL byte at {text.index(chr(0))}): expected a CSV "
                                  "table (text) or a .parquet file")
    lines = text.lstrip("\ufeff").splitlines()[:6]
    if len(lines) > 1 and not text.endswith(("\n", "\r")):
        lines = lines[:-1]  # the sniffed bytes may end inside a line

    def fields(d: str) -> int:
        """Columns the delimiter ``d`` gives every line, or 0 when the lines disagree."""
        counts = {len(row) for row in csv.reader(lines, delimiter=d)}
        return counts.pop() if len(counts) == 1 else 0

    return max(DELIMITERS, key=lambda d: (fields(d), d == ",")) if lines else ","


def read_table(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a Parquet or CSV file as float arrays (non-numeric columns are skipped). A CSV file's delimiter
    is a comma, a semicolon or a tab (:func:`_csv_delimiter`); its decimals are points."""
    p = Path(path)
    if not p.exists():
        raise IdentificationError(f"log file {p}: not found: expected a Parquet or CSV file")
    suffix = p.suffix.lower()
    try:
        if suffix in (".parquet", ".pq"):
            import pyarrow.parquet as pq

            table = pq.read_table(p)
        elif suffix in (".csv", ".txt"):
            import pyarrow.csv as pcsv

            delimiter = _csv_delimiter(p)
            table = pcsv.read_csv(p, parse_options=pcsv.ParseOptions(delimiter=delimiter))
            _no_decimal_commas(p, table, delimiter)
        else:
            raise IdentificationError(f"log file {p}: unknown format '{suffix}': expected .parquet or .csv")
    except IdentificationError:
        raise
    except Exception as exc:  # pyarrow raises many types for unreadable files
        why = str(exc).encode("ascii", "backslashreplace").decode()[:300]
        raise IdentificationError(f"log file {p}: cannot be read ({why}): expected a Parquet or CSV table") from exc
    return table_columns(table)


def _no_decimal_commas(p: Path, table, delimiter: str) -> None:
    """Refuse a CSV table whose numbers are written with decimal commas (``8,879``: a locale's export) rather than
    read them as text columns and report them missing: a text column whose first cells all read as numbers once a
    comma is a point, at least one with a comma."""
    if delimiter == ",":
        return
    import pyarrow as pa

    for name in table.column_names:
        col = table.column(name)
        if not pa.types.is_string(col.type) or len(col) == 0:
            continue
        cells = [c for c in col.slice(0, 100).to_pylist() if c]
        cell = next((c for c in cells if "," in c), None)
        if cell is not None and all(_number(c.replace(",", ".")) for c in cells):
            raise IdentificationError(f"log file {p}: column '{name}' holds {cell!r}, a number with a decimal comma: "
                                      "expected decimal points (export the table with '.' as the decimal separator)")


def table_columns(table: object) -> dict[str, np.ndarray]:
    """Numeric columns of a pyarrow Table or a mapping of name -> array, as float64 arrays."""
    if hasattr(table, "column_names") and hasattr(table, "column"):
        raw = {name: table.column(name).to_numpy(zero_copy_only=False) for name in table.column_names}
    elif isinstance(table, Mapping):
        raw = dict(table)
    else:
        raise IdentificationError(f"table: got {type(table).__name__}: expected a file, a pyarrow Table or a mapping")
    out = {}
    for name, values in raw.items():
        try:
            arr = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError):
            arr = _mostly_numbers(str(name), values)
            if arr is None:
                continue  # text columns (labels, notes) are not signals
        if arr.ndim == 1:
            out[str(name)] = arr
    return out


def _mostly_numbers(name: str, values) -> np.ndarray | None:
    """A column of numbers with a few cells that are not (e.g. ``abc`` in one row of a torque column): those cells
    read as NaN (the rows are then dropped, and counted, like other NaN rows) with a warning naming the column, how
    many cells and the first one; None for a text column (at most half of its cells are numbers)."""
    cells = np.asarray(values, dtype=object)
    if cells.ndim != 1:
        return None
    arr = np.full(cells.size, np.nan)
    bad = []
    for i, v in enumerate(cells):
        try:
            arr[i] = float(v) if v is not None else np.nan
        except (TypeError, ValueError):
            bad.append(i)
    if len(bad) * 2 >= cells.size:
        return None
    log.warning("column '%s': %d of %d cells are not numbers (first: data row %d from 0, %r): read as NaN, their "
                "rows dropped", name, len(bad), cells.size, bad[0], cells[bad[0]])
    return arr


def _number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def servotau_joints(columns: Mapping[str, np.ndarray]) -> list[str]:
    """Joints of a servotau log (those with ``q/<joint>`` and ``q_des/<joint>``)."""
    return [c[2:] for c in columns if c.startswith("q/") and f"q_des/{c[2:]}" in columns]


def resolve_roles(columns: Mapping[str, np.ndarray], joint: str | None, roles: Mapping[str, str] | None) -> tuple[
    dict[str, str], str | None
]:
    """Column of each role, and the joint, for one of the three layouts of a workbench dataset (roles, servotau
    log, single-joint table: :mod:`servotau.identification.workbench.data`)."""
    names = list(columns)
    roles = dict(roles or {})
    for role, col in roles.items():
        if role not in ROLES:
            raise IdentificationError(f"column role '{role}': expected one of {list(ROLES)}")
        if col not in columns:
            raise IdentificationError(f"column '{col}' (role {role}): not in the table: expected one of {names}")
    joints = servotau_joints(columns)
    if joints and not ({"target", "command"} & set(roles)):
        if joint is None:
            if len(joints) > 1:
                raise IdentificationError(f"the log has joints {joints}: expected --joint to choose one")
            joint = joints[0]
        if joint not in joints:
            raise IdentificationError(f"joint '{joint}': not in the log: expected one of {joints}")
        found = {"position": f"q/{joint}", "command": f"q_des/{joint}"}
        for role, candidates in (("torque", (f"est/tau/{joint}", f"tau/{joint}")),
                                 ("velocity", (f"est/dq/{joint}", f"dq/{joint}"))):
            col = next((c for c in candidates if c in columns), None)
            if col is not None:
                found[role] = col
        if "t" in columns:
            found["time"] = "t"
        if "torque" not in found and "torque" not in roles:
            raise IdentificationError(
                f"joint '{joint}': no torque column: expected 'est/tau/{joint}' (a controller's log), a servotau "
                "Parquet log with its sensors (the off-line estimator then computes it), or a mapping "
                "torque=COLUMN"
            )
        return {**found, **roles}, joint
    if not roles or not ({"target", "command"} & set(roles)):
        defaults = {"time": "t", "position": "q", "command": "q_des", "torque": "tau", "velocity": "dq",
                    "acceleration": "ddq", "segment": "segment"}
        found = {role: col for role, col in defaults.items() if col in columns}
        roles = {**found, **roles}
        missing = [defaults[r] for r in ("command", "position") if r not in roles]
        if missing:
            raise IdentificationError(
                f"missing column(s) {missing}: expected a single-joint table with columns t, q, q_des, tau "
                f"(optional dq), a servotau log with q/<joint>, or a role mapping (e.g. target=COLUMN); "
                f"the table has {names}"
            )
        return roles, joint
    if "target" not in roles and not {"command", "position"} <= set(roles):
        raise IdentificationError("role 'command' needs role 'position' too (target = command - position)")
    if "time" not in roles and "t" in columns:
        roles["time"] = "t"
    return roles, joint


def table_format(path: str | Path) -> str:
    """``"csv"`` or ``"parquet"``: the format :func:`write_table` writes to ``path``, by its suffix.

    Raises:
        IdentificationError: Another suffix (checked before any work that would end in writing it).
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".csv":
        return "csv"
    if suffix in (".parquet", ".pq"):
        return "parquet"
    raise IdentificationError(f"{path}: unknown format '{Path(path).suffix}': expected .parquet or .csv")


def write_table(columns: Mapping[str, np.ndarray], path: str | Path) -> Path:
    """Write columns to a Parquet (``.parquet``) or CSV (``.csv``) file; return the path."""
    import pyarrow as pa

    p = Path(path)
    fmt = table_format(p)
    p.parent.mkdir(parents=True, exist_ok=True)
    table = pa.table({k: np.asarray(v) for k, v in columns.items()})
    if fmt == "csv":
        import pyarrow.csv as pcsv

        pcsv.write_csv(table, p)
    else:
        import pyarrow.parquet as pq

        pq.write_table(table, p)
    return p
