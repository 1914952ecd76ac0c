"""Parquet log under a slow disk: append never waits for the writer; dropped chunks are counted and reported."""

from __future__ import annotations

import logging
import threading
import time

import numpy as np
import pytest

from servotau.errors import HalError
from servotau.hal import LogReader, LogWriter
from servotau.simrobot.fake import FakeRobot


def test_a_stalled_writer_never_blocks_a_realtime_append_and_overflow_is_counted(tmp_path, monkeypatch, caplog):
    """realtime=True: while the writer thread is stuck on the disk, append() keeps returning: up to max_pending chunks
    queue, the next ones are dropped and counted; once the disk is back, close() writes the queued chunks and reports
    the loss."""
    robot = FakeRobot(seed=1)
    path = tmp_path / "slow.parquet"
    stalled, release, writing = threading.Event(), threading.Event(), threading.Event()
    original = LogWriter._write_chunk

    def slow_disk(self, job):
        writing.set()
        if not release.is_set():
            stalled.set()
            release.wait(30.0)
        original(self, job)

    monkeypatch.setattr(LogWriter, "_write_chunk", slow_disk)
    w = LogWriter(path, robot.info, truth=False, extra=[], chunk_rows=10, max_pending=2, realtime=True)
    frames = [robot.read()]
    for _ in range(99):
        robot.step(frames[-1].q)
        frames.append(robot.read())
    done = threading.Event()

    def loop():  # 100 rows: 10 chunks; the first sticks in the writer, 2 queue, 7 are dropped
        for k, f in enumerate(frames):
            w.append(f, f.q)
            if k == 9:
                writing.wait(30.0)  # the writer has taken the first chunk (and hangs on it)
        done.set()

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    assert done.wait(30.0), "append() blocked on the stalled writer"
    assert stalled.is_set()
    assert w.rows == 100 and w.dropped_chunks == 7 and w.dropped_rows == 70
    release.set()
    with caplog.at_level(logging.WARNING, logger="servotau.hal.log"):
        w.close()
    assert "70 of 100 rows dropped in 7 chunks" in caplog.text
    seq = LogReader(path).columns["seq"]
    np.testing.assert_array_equal(seq, [f.seq for f in frames[:30]])  # the written chunks, whole and in order


def test_a_slow_writer_makes_a_lockstep_append_wait_and_loses_nothing(tmp_path, monkeypatch):
    """realtime=False (lock-step, offline): a chunk that finds the queue full waits for the writer; every row is in
    the log."""
    robot = FakeRobot(seed=2)
    original = LogWriter._write_chunk

    def slow_disk(self, job):
        time.sleep(0.02)
        original(self, job)

    monkeypatch.setattr(LogWriter, "_write_chunk", slow_disk)
    path = tmp_path / "lockstep.parquet"
    with LogWriter(path, robot.info, truth=False, extra=[], chunk_rows=10, max_pending=1) as w:
        f = robot.read()
        seqs = []
        for _ in range(200):
            w.append(f, f.q)
            seqs.append(f.seq)
            robot.step(f.q)
            f = robot.read()
    assert w.dropped_rows == 0
    np.testing.assert_array_equal(LogReader(path).columns["seq"], seqs)


def test_max_pending_is_validated(tmp_path):
    with pytest.raises(HalError, match="max_pending = 0: expected >= 1"):
        LogWriter(tmp_path / "x.parquet", FakeRobot().info, max_pending=0)
