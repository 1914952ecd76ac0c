"""The project's log format: Parquet, one row per tick, RobotInfo as JSON in the schema metadata.

Columns (float64 unless said otherwise)::

    t                                  [s] robot time
    seq                                int64, tick number
    q/<joint>, q_des/<joint>           [rad] measured and desired angles (q_des NaN: none / servo off)
    imu/gyro_x|y|z                     [rad/s]
    imu/acc_x|y|z                      [m/s^2] specific force
    ft/<sensor>/fx|fy|fz|tx|ty|tz      [N, N m] HAL sign convention (hal/types.py)
    status/<name>                      uint8, STATUS_* of each sensor
    true/<field>/<...>                 optional ground truth, e.g. true/tau/<joint>, true/q/<joint>
    <anything else>                    free extra columns declared up front, e.g. est/tau/<joint>

:class:`LogWriter` writes every ``chunk_rows`` rows a complete Parquet chunk to ``<path>.parts/``,
so a crash loses at most the last chunk; :meth:`LogWriter.close` merges the chunks into ``<path>``.
:func:`read_log` also reads an unclosed log from its chunks.

Full chunks go to a writer thread through a bounded queue of ``max_pending`` chunks. A chunk that finds the
queue full (the disk or the writer thread is too slow) waits for room, so nothing is lost; with
``realtime=True`` (a loop on the wall clock) it is dropped instead, counted in :attr:`LogWriter.dropped_rows`
and reported when the log is closed: such a loop never stalls on the log, which then misses rows (their
``seq`` values are absent). A lock-step or offline run keeps every row.
"""

from __future__ import annotations

import logging
import os
import queue
import shutil
import threading
import weakref
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import HalError
from .types import STATUS_NAMES, GroundTruth, RobotInfo, SensorFrame
from .wire.protocol import info_from_json, info_to_json, truth_layout

if TYPE_CHECKING:
    import pyarrow as pa

logger = logging.getLogger(__name__)

LOG_FORMAT_VERSION = "1"
META_INFO = "servotau.robot_info"
META_FORMAT = "servotau.log_format"
WRENCH_AXES = ("fx", "fy", "fz", "tx", "ty", "tz")
_TRUTH_ROWS = {"sole_contact_forces": (("right", "left"), ("x", "y", "z"))}
_TRUTH_SUFFIXES = {
    "base_position": ("x", "y", "z"),
    "base_quat_wxyz": ("w", "x", "y", "z"),
    "base_velocity": ("vx", "vy", "vz", "wx", "wy", "wz"),
    "external_wrench": WRENCH_AXES,
}


def _pa():
    # pyarrow takes ~0.25 s to import: only when a log is actually written or read.
    import pyarrow as pa
    import pyarrow.parquet as pq

    return pa, pq


def parts_dir(path: str | Path) -> Path:
    """Folder of the chunks of a log being written (removed once the log is closed)."""
    p = Path(path)
    return p.with_name(p.name + ".parts")


def frame_columns(info: RobotInfo) -> list[str]:
    """Float columns of a SensorFrame (without t, seq and status), in frame order."""
    cols = [f"q/{j}" for j in info.joint_names]
    cols += [f"imu/gyro_{a}" for a in "xyz"] + [f"imu/acc_{a}" for a in "xyz"]
    cols += [f"ft/{s}/{a}" for s in info.ft_sensor_names for a in WRENCH_AXES]
    return cols


def truth_columns(info: RobotInfo) -> list[str]:
    """``true/...`` columns, in the order of ``GroundTruth.to_vector()``."""
    cols = []
    for field, shape in truth_layout(info.nq):
        if field in _TRUTH_SUFFIXES and shape == (len(_TRUTH_SUFFIXES[field]),):
            cols += [f"true/{field}/{s}" for s in _TRUTH_SUFFIXES[field]]
        elif shape == (info.nq,):
            cols += [f"true/{field}/{j}" for j in info.joint_names]
        elif field in _TRUTH_ROWS and shape == tuple(len(x) for x in _TRUTH_ROWS[field]):
            rows, axes = _TRUTH_ROWS[field]
            cols += [f"true/{field}/{r}/{a}" for r in rows for a in axes]
        elif len(shape) == 2 and shape == (len(info.ft_sensor_names), 6):
            cols += [f"true/{field}/{s}/{a}" for s in info.ft_sensor_names for a in WRENCH_AXES]
        elif len(shape) == 2:
            cols += [f"true/{field}/{r}/{c}" for r in range(shape[0]) for c in range(shape[1])]
        else:
            cols += [f"true/{field}/{i}" for i in range(int(np.prod(shape)))]
    return cols


class LogWriter:
    """Records one row per tick into preallocated arrays, flushed to Parquet chunk by chunk.

    The columns are fixed by the constructor, or else by the first :meth:`append`: ``truth=None``
    records ground truth if the first row has it; ``extra=None`` takes the extras of the first row.
    An array-valued extra of ``nq`` values named ``"est/tau"`` gives columns ``est/tau/<joint>``
    (other sizes: ``<name>/<i>``). Use as a context manager: the log is closed (and nothing recorded
    is lost) even on an error.

    Args:
        path: the ``.parquet`` file written by :meth:`close`.
        info: the robot (stored as JSON in the schema metadata).
        truth: record ``true/...`` columns (None: if the first row has ground truth).
        extra: extra column names, or array-valued names (None: those of the first row).
        chunk_rows: rows per chunk; a crash loses at most the last chunk (and the one being written).
        metadata: extra key -> value strings stored in the schema metadata (scenario, seed...).
        background: write the chunks in a background thread (the control loop never waits for the disk).
        max_pending: chunks waiting for the background writer at most; a chunk beyond waits for room, or with
            ``realtime`` is dropped and counted (:attr:`dropped_rows`).
        realtime: the caller's loop runs on the wall clock: never wait for the writer (drop instead).
    """

    def __init__(
        self,
        path: str | Path,
        info: RobotInfo,
        *,
        truth: bool | None = None,
        extra: Sequence[str] | None = None,
        chunk_rows: int = 1000,
        metadata: Mapping[str, str] | None = None,
        background: bool = True,
        max_pending: int = 8,
        realtime: bool = False,
    ):
        self.path = Path(path)
        self.info = info
        self.chunk_rows = int(chunk_rows)
        if self.chunk_rows < 1:
            raise HalError(f"LogWriter chunk_rows = {chunk_rows}: expected >= 1")
        if int(max_pending) < 1:
            raise HalError(f"LogWriter max_pending = {max_pending}: expected >= 1")
        _pa()  # import pyarrow now, not in the first append (a quarter of a second in the caller's loop)
        self._want_truth, self._want_extra = truth, extra
        self._metadata = {META_INFO: info_to_json(info), META_FORMAT: LOG_FORMAT_VERSION, **(metadata or {})}
        self.schema = None  # fixed by the constructor or the first append
        self._slots: dict[tuple[str, int], np.ndarray] = {}  # (extra name, size) -> column indices
        self._n = 0  # rows in the buffer
        self._chunks = 0
        self.rows = 0  # rows appended in total
        self.dropped_rows = 0  # rows of the chunks dropped because the writer queue was full
        self.dropped_chunks = 0
        self.realtime = bool(realtime)
        self.closed = False
        _open_writers.add(self)
        self._error: BaseException | None = None  # of the background writer, raised by append/close
        self._queue: queue.Queue | None = queue.Queue(maxsize=int(max_pending)) if background else None
        self._free: queue.SimpleQueue = queue.SimpleQueue()  # row buffers the writer thread is done with
        self._thread: threading.Thread | None = None
        parts = parts_dir(self.path)
        if parts.exists():
            shutil.rmtree(parts)
        parts.mkdir(parents=True)
        if truth is not None and extra is not None:
            self._setup(truth, list(extra))

    def _alloc(self) -> None:
        """Fresh row buffers: one the writer thread has finished with, else new ones."""
        try:
            self._f, self._seq, self._status = self._free.get_nowait()
            return
        except queue.Empty:
            pass
        self._f = np.empty((self.chunk_rows, len(self._float_cols)))
        self._seq = np.empty(self.chunk_rows, dtype=np.int64)
        self._status = np.empty((self.chunk_rows, len(STATUS_NAMES)), dtype=np.uint8)

    def _expand(self, name: str, value) -> list[str]:
        size = np.size(value)
        if np.ndim(value) == 0:
            return [name]
        if np.ndim(value) == 1 and size == self.info.nq:
            return [f"{name}/{j}" for j in self.info.joint_names]
        return [f"{name}/{i}" for i in range(size)]

    def _setup(self, truth: bool, extra: list[str]) -> None:
        pa, _ = _pa()
        info, nq = self.info, self.info.nq
        self._frame_cols = frame_columns(info)
        self._truth_cols = truth_columns(info) if truth else []
        self._extra = extra
        float_cols = ["t", *self._frame_cols[:nq], *[f"q_des/{j}" for j in info.joint_names],
                      *self._frame_cols[nq:], *self._truth_cols, *extra]
        reserved = ("t", "seq", "q/", "q_des/", "imu/", "ft/", "status/", "true/")
        if len(set(float_cols)) != len(float_cols) or any(
                c in reserved or c.startswith(reserved[2:]) for c in extra):
            raise HalError(f"LogWriter extra columns {extra}: expected distinct names outside the standard "
                           f"columns {list(reserved)}")
        self._float_cols = float_cols
        self._col = {c: i for i, c in enumerate(float_cols)}
        n_frame = len(self._frame_cols)
        self._s_q = slice(1, 1 + nq)
        self._s_q_des = slice(1 + nq, 1 + 2 * nq)
        self._s_rest = slice(1 + 2 * nq, 1 + nq + n_frame)
        self._s_truth = slice(self._s_rest.stop, self._s_rest.stop + len(self._truth_cols))
        # Row-major buffers (a row is written contiguously), transposed once per chunk.
        self._alloc()
        fields = [pa.field("t", pa.float64()), pa.field("seq", pa.int64())]
        fields += [pa.field(c, pa.float64()) for c in float_cols[1 : self._s_truth.start]]
        fields += [pa.field(f"status/{s}", pa.uint8()) for s in STATUS_NAMES]
        fields += [pa.field(c, pa.float64()) for c in float_cols[self._s_truth.start :]]
        self.schema = pa.schema(fields, metadata=self._metadata)

    @property
    def columns(self) -> list[str]:
        """Column names (empty until the schema is fixed)."""
        return self.schema.names if self.schema is not None else []

    @property
    def truth_decided(self) -> bool:
        """Whether the ``true/...`` columns are fixed (by the constructor, :meth:`set_truth` or the first row)."""
        return self.schema is not None or self._want_truth is not None

    def set_truth(self, record: bool) -> None:
        """Record the ``true/...`` columns (NaN in rows without truth) or not; HalError after the first row."""
        if self.schema is not None:
            raise HalError(f"{self.path}: set_truth after the first row: expected it before (the columns are fixed)")
        self._want_truth = bool(record)

    def append(
        self,
        frame: SensorFrame,
        q_des: np.ndarray | None = None,
        truth: GroundTruth | None = None,
        extra: Mapping[str, float | np.ndarray] | None = None,
    ) -> None:
        """Record one tick: the frame, the desired angles [rad] (None: NaN), ground truth, extras."""
        if self.closed:
            raise HalError(f"{self.path}: log is closed: expected an open LogWriter")
        if self._error is not None:
            raise HalError(f"{self.path}: writing a chunk failed: {self._error}") from self._error
        if self.schema is None:
            want_truth = truth is not None if self._want_truth is None else self._want_truth
            if self._want_extra is None:
                names = [c for k, v in (extra or {}).items() for c in self._expand(k, v)]
            else:
                names = list(self._want_extra)
            self._setup(want_truth, names)
        i = self._n
        row = self._f[i]
        row.fill(np.nan)
        row[0] = frame.time
        self._seq[i] = frame.seq
        row[self._s_q] = frame.q
        if q_des is not None:
            row[self._s_q_des] = q_des
        r = self._s_rest.start
        n_ft = 6 * frame.wrenches.shape[0]
        row[r : r + 3] = frame.imu_angular_velocity
        row[r + 3 : r + 6] = frame.imu_linear_acceleration
        row[r + 6 : r + 6 + n_ft] = frame.wrenches.ravel()
        self._status[i] = frame.status
        if truth is not None and self._truth_cols:
            row[self._s_truth] = truth.to_vector()
        if extra:
            for name, value in extra.items():
                row[self._slot(name, value)] = np.ravel(value) if np.ndim(value) else value
        self._n += 1
        self.rows += 1
        if self._n == self.chunk_rows:
            self.flush()

    def _slot(self, name: str, value) -> np.ndarray | int:
        key = (name, np.size(value) if np.ndim(value) else -1)
        idx = self._slots.get(key)
        if idx is None:
            cols = self._expand(name, value)
            missing = [c for c in cols if c not in self._col or self._col[c] < self._s_truth.stop]
            if missing:
                raise HalError(f'log column "{missing[0]}" was not declared: expected one of {self._extra} '
                               "(extras are fixed by the constructor or the first row)")
            idx = self._slots[key] = np.array([self._col[c] for c in cols]) if np.ndim(value) else self._col[cols[0]]
        return idx

    def _table(self, f: np.ndarray, seq: np.ndarray, status: np.ndarray) -> pa.Table:
        pa, _ = _pa()
        f64, u8 = pa.float64(), pa.uint8()
        ts = self._s_truth.start
        f, st = np.ascontiguousarray(f.T), np.ascontiguousarray(status.T)
        arrays = [pa.array(f[0], type=f64), pa.array(seq, type=pa.int64())]
        arrays += [pa.array(f[j], type=f64) for j in range(1, ts)]
        arrays += [pa.array(st[j], type=u8) for j in range(len(STATUS_NAMES))]
        arrays += [pa.array(f[j], type=f64) for j in range(ts, len(self._float_cols))]
        return pa.Table.from_arrays(arrays, schema=self.schema)

    def _write_chunk(self, job: tuple) -> None:
        _, pq = _pa()
        f, seq, status, k = job
        part = parts_dir(self.path) / f"part-{k:06d}.parquet"
        tmp = part.with_suffix(".tmp")
        pq.write_table(self._table(f, seq, status), tmp, compression="none", use_dictionary=False)
        os.replace(tmp, part)

    def _worker(self) -> None:
        while (job := self._queue.get()) is not None:
            try:
                self._write_chunk(job)
            except BaseException as exc:  # reported by the next append() or close()
                self._error = exc
            f, seq, status, _ = job
            if len(f) == self.chunk_rows and f.base is None:  # a whole buffer: back to append()
                self._free.put((f, seq, status))

    def flush(self) -> None:
        """Hand the buffered rows over as one complete Parquet chunk (atomic rename); with a background writer
        whose queue is full, wait for room, or with ``realtime`` drop them (counted in :attr:`dropped_rows`)."""
        if self._n == 0 or self.schema is None:
            return
        n = self._n
        whole = n == self.chunk_rows
        job = (self._f if whole else self._f[:n], self._seq if whole else self._seq[:n],
               self._status if whole else self._status[:n], self._chunks)
        self._n = 0
        if self._queue is None:
            self._chunks += 1
            self._write_chunk(job)
            return
        if self._thread is None:
            self._thread = threading.Thread(target=self._worker, name=f"LogWriter({self.path.name})",
                                            daemon=True)
            self._thread.start()
        try:
            self._queue.put(job, block=not self.realtime)
        except queue.Full:  # the writer is behind: keep the loop going, lose these rows (reused buffers)
            self.dropped_rows += n
            self.dropped_chunks += 1
            if self.dropped_chunks == 1:
                logger.warning("%s: the log writer is behind (%d chunks queued): dropping rows", self.path,
                               self._queue.maxsize)
            return
        self._chunks += 1
        self._alloc()  # the job owns the old buffers

    def close(self) -> None:
        """Flush, wait for the writer and merge the chunks into the final file; idempotent."""
        if self.closed:
            return
        self.closed = True
        _open_writers.discard(self)
        if self.schema is None:  # no row: an empty log with the standard columns
            self._setup(bool(self._want_truth), list(self._want_extra or []))
        self.flush()
        if self._thread is not None:
            self._queue.put(None)  # blocks while the queue is full: close() may wait, append() never does
            self._thread.join()
        finalize_log(self.path, self.schema)
        if self.dropped_rows:
            logger.warning("%s: %d of %d rows dropped in %d chunks (the log writer was behind; max_pending = %d)",
                           self.path, self.dropped_rows, self.rows, self.dropped_chunks, self._queue.maxsize)
        if self._error is not None:
            raise HalError(f"{self.path}: writing a chunk failed, the log misses rows: {self._error}") \
                from self._error

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


_open_writers: weakref.WeakSet = weakref.WeakSet()


def _close_open_writers() -> None:
    """At interpreter exit: close the logs nobody closed (nothing recorded is lost)."""
    for w in list(_open_writers):
        try:
            w.close()
        except Exception as exc:  # keep closing the others
            logger.error("closing %s at exit failed: %s", w.path, exc)


# Runs before the interpreter joins threads, while the writer threads still run.
if hasattr(threading, "_register_atexit"):
    threading._register_atexit(_close_open_writers)


def finalize_log(path: str | Path, schema: pa.Schema | None = None) -> Path:
    """Merge the chunks of ``<path>.parts/`` into ``path`` and remove them (also recovers a crashed log)."""
    _, pq = _pa()
    path = Path(path)
    parts = sorted(parts_dir(path).glob("part-*.parquet"))
    if schema is None:
        if not parts:
            raise HalError(f"{path}: no chunks in {parts_dir(path)}: expected a log being written")
        schema = pq.read_schema(parts[0])
    tmp = path.with_name(path.name + ".tmp")
    with pq.ParquetWriter(tmp, schema) as w:
        for p in parts:
            w.write_table(pq.read_table(p))
    os.replace(tmp, path)
    shutil.rmtree(parts_dir(path), ignore_errors=True)
    return path


class LogReader:
    """A log in memory: ``info``, the Arrow ``table``, numpy ``columns`` and helpers."""

    def __init__(self, path: str | Path):
        pa, pq = _pa()
        self.path = Path(path)
        if self.path.exists():
            self.table = pq.read_table(self.path)
        elif parts_dir(self.path).exists():
            parts = sorted(parts_dir(self.path).glob("part-*.parquet"))
            if not parts:
                raise HalError(f"{self.path}: no such log (and no chunk in {parts_dir(self.path)})")
            logger.warning("%s was not closed: reading %d chunks from %s", self.path, len(parts),
                           parts_dir(self.path))
            self.table = pa.concat_tables([pq.read_table(p) for p in parts])
        else:
            raise HalError(f"{self.path}: no such log file")
        meta = {k.decode(): v.decode() for k, v in (self.table.schema.metadata or {}).items()}
        if META_INFO not in meta:
            raise HalError(f"{self.path}: no '{META_INFO}' in the Parquet metadata: expected a servotau log")
        self.metadata = meta
        self.info = info_from_json(meta[META_INFO])
        self._columns: dict[str, np.ndarray] | None = None

    def __len__(self) -> int:
        return self.table.num_rows

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """Every column as a numpy array (computed once)."""
        if self._columns is None:
            self._columns = {n: self.table.column(n).to_numpy() for n in self.table.column_names}
        return self._columns

    def matrix(self, names: Sequence[str]) -> np.ndarray:
        """``(rows, len(names))`` float array of the given columns."""
        cols = self.columns
        missing = [n for n in names if n not in cols]
        if missing:
            raise HalError(f"{self.path}: no column {missing[0]!r}: expected one of {list(cols)[:12]}...")
        out = np.empty((len(self), len(names)))
        for j, n in enumerate(names):
            out[:, j] = cols[n]
        return out

    def joints(self, prefix: str) -> np.ndarray:
        """``(rows, nq)`` array of ``<prefix>/<joint>`` columns, e.g. ``"q"``, ``"q_des"``, ``"true/tau"``."""
        return self.matrix([f"{prefix}/{j}" for j in self.info.joint_names])

    @property
    def has_truth(self) -> bool:
        return all(c in self.columns for c in truth_columns(self.info))

    def truth(self, row: int) -> GroundTruth | None:
        """Ground truth of row ``row``, or None if the log has no (complete) truth columns."""
        if not self.has_truth:
            return None
        vec = np.array([self.columns[c][row] for c in truth_columns(self.info)])
        return GroundTruth.from_vector(float(self.columns["t"][row]), int(self.columns["seq"][row]), vec,
                                       self.info.nq)

    def frames(self) -> Iterator[SensorFrame]:
        """The recorded frames, in order, equal to the recorded arrays."""
        info, cols = self.info, self.columns
        fc = frame_columns(info)
        nq, n_ft = info.nq, len(info.ft_sensor_names)
        data = self.matrix(fc)
        status = np.column_stack([cols[f"status/{s}"] for s in STATUS_NAMES]).astype(np.uint8)
        t, seq = cols["t"], cols["seq"]
        for i in range(len(self)):
            row = data[i]
            yield SensorFrame(
                time=float(t[i]), seq=int(seq[i]), q=row[:nq], imu_angular_velocity=row[nq : nq + 3],
                imu_linear_acceleration=row[nq + 3 : nq + 6], wrenches=row[nq + 6 :].reshape(n_ft, 6),
                status=status[i],
            )


def read_log(path: str | Path) -> tuple[RobotInfo, dict[str, np.ndarray]]:
    """``(RobotInfo, {column: numpy array})`` of a log."""
    log = LogReader(path)
    return log.info, log.columns


def frames(log: str | Path | LogReader) -> Iterator[SensorFrame]:
    """Replay the frames of a log (path or :class:`LogReader`)."""
    return (log if isinstance(log, LogReader) else LogReader(log)).frames()

