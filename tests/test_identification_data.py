"""Tests of the identification data layer (identification/data/): segments, shifts and held-out splits, with the
rule of each caller (the paper's pipeline, the workbench) pinned."""

import numpy as np
import pytest

from servotau.errors import IdentificationError
from servotau.identification.data import (
    blocked_folds,
    holdout_split,
    read_table,
    resolve_roles,
    segments,
    shift,
    time_blocks,
    write_table,
)


def test_segments_by_tick_cut_at_a_seq_jump_and_at_any_irregular_time_step():
    """The pipeline's rule: seq steps by one and the time by one period (relative 1e-3), over every row."""
    t = np.array([0.0, 1e-3, 2e-3, 3e-3, 5e-3, 6e-3, 7e-3, 8e-3])
    seq = np.array([0, 1, 2, 3, 5, 6, 9, 10])
    assert segments(t, 1e-3, seq=seq) == [(0, 4), (4, 6), (6, 8)]
    t2 = np.arange(6) * 1e-3
    t2[3:] += 0.3e-3  # a step of 1.3 periods: not a tick
    assert segments(t2, 1e-3, seq=np.arange(6)) == [(0, 3), (3, 6)]
    assert segments(np.array([]), 1e-3, seq=np.array([], dtype=int)) == []


def test_segments_of_valid_rows_cut_only_at_gaps_longer_than_max_gap():
    """The workbench's rule: runs of valid rows, cut where the time step exceeds max_gap periods."""
    t = np.array([0.0, 1.0, 2.0, 3.4, 5.0, 6.0, 7.0, 8.0])  # steps 1, 1, 1.4 (kept), 1.6 (cut), 1, 1, 1
    valid = np.array([True, True, True, True, True, False, True, True])
    assert segments(t, 1.0, valid=valid, max_gap=1.5) == [(0, 4), (4, 5), (6, 8)]
    assert segments(None, None, valid=valid) == [(0, 5), (6, 8)]
    assert segments(None, None, valid=np.zeros(3, bool)) == []
    with pytest.raises(IdentificationError, match="expected equal"):
        segments(t, 1.0, valid=valid[:3])


def test_shift_fills_with_nan_or_holds_the_edges():
    x = np.arange(5.0)
    np.testing.assert_array_equal(shift(x, 2), [2, 3, 4, np.nan, np.nan])
    np.testing.assert_array_equal(shift(x, -2), [np.nan, np.nan, 0, 1, 2])
    np.testing.assert_array_equal(shift(x, 2, fill="hold"), [2, 3, 4, 4, 4])
    np.testing.assert_array_equal(shift(x, -2, fill="hold"), [0, 0, 0, 1, 2])
    m = np.arange(6.0).reshape(3, 2)
    np.testing.assert_array_equal(shift(m, 1), [[2, 3], [4, 5], [np.nan, np.nan]])
    out = shift(x, 0)
    assert out is not x and np.array_equal(out, x)
    with pytest.raises(IdentificationError, match="fill"):
        shift(x, 1, fill="zero")


def test_shift_past_a_short_run_keeps_its_length():
    """A run shorter than the shift (align_torque shifts each run of a log) is all NaN or all its edge value."""
    from servotau.actuator.signals import per_run

    x = np.arange(3.0)
    for k in (3, 7, -3, -7):
        assert np.isnan(shift(x, k)).all() and len(shift(x, k)) == 3
    np.testing.assert_array_equal(shift(x, 7, fill="hold"), [2, 2, 2])
    np.testing.assert_array_equal(shift(x, -7, fill="hold"), [0, 0, 0])
    np.testing.assert_array_equal(shift(x, 3, fill="hold"), [2, 2, 2])
    np.testing.assert_array_equal(shift(np.arange(6.0).reshape(3, 2), -4, fill="hold"), [[0, 1]] * 3)
    assert shift(np.empty(0), 2, fill="hold").shape == (0,)
    runs = per_run(lambda v: shift(v, 3, fill="hold"), (0, 2), np.arange(8.0))
    np.testing.assert_array_equal(runs, [1, 1, 5, 6, 7, 7, 7, 7])


def test_holdout_split_holds_out_every_nth_time_block_then_downsamples_each_set():
    t = 0.5 + np.arange(9000) * 1e-3  # 9 s from 0.5 s: blocks counted from t[0]
    valid = np.ones(len(t), bool)
    valid[100:200] = False
    train, held = holdout_split(t, valid, 1.0, 3, downsample=10)
    block = time_blocks(t, 1.0)
    assert set(np.unique(block[held])) == {2, 5, 8} and not (train & held).any()
    assert not (train | held)[100:200].any()
    idx = np.flatnonzero(valid & (block % 3 != 2))
    np.testing.assert_array_equal(np.flatnonzero(train), idx[::10])


def test_blocked_folds_equal_blocks_or_segment_groups_with_a_guard():
    folds = blocked_folds(100, 4, guard=5)
    assert [f.label for f in folds] == [f"block {i}/4" for i in range(1, 5)]
    assert folds[1].test[0] == 25 and not folds[1].train[20:55].any() and folds[1].train[:20].all()
    seg = np.repeat([1.0, 2.0, 3.0, 4.0], 25)
    by_segment = blocked_folds(100, 2, seg)
    assert [f.label for f in by_segment] == ["segment 1-2", "segment 3-4"]
    with pytest.raises(IdentificationError, match="at least 2"):
        blocked_folds(100, 1)


def test_resolve_roles_of_a_servotau_log_and_of_a_single_joint_table():
    cols = {"t": np.zeros(3), "q/J": np.zeros(3), "q_des/J": np.zeros(3), "est/tau/J": np.zeros(3)}
    roles, joint = resolve_roles(cols, None, None)
    assert joint == "J" and roles == {"position": "q/J", "command": "q_des/J", "torque": "est/tau/J", "time": "t"}
    roles, joint = resolve_roles({"q": np.zeros(3), "q_des": np.zeros(3)}, None, None)
    assert joint is None and roles == {"position": "q", "command": "q_des"}


def test_a_numeric_column_with_a_text_cell_reads_it_as_nan_and_says_so(tmp_path, caplog):
    """One ``abc`` in a torque column of a CSV: the column is kept (the cell NaN, its row dropped later like any NaN
    row) with a warning naming the column, the count and the first cell; a column of labels is not a signal."""
    t = np.arange(6) * 1e-3
    tau = [f"{x:.3f}" for x in np.sin(t)]
    tau[3] = "abc"
    rows = [f"{a:.3f},{b},run{i % 2}" for i, (a, b) in enumerate(zip(t, tau, strict=True))]
    path = tmp_path / "log.csv"
    path.write_text("t,tau,label\n" + "\n".join(rows) + "\n")
    with caplog.at_level("WARNING"):
        cols = read_table(path)
    assert set(cols) == {"t", "tau"}
    assert np.isnan(cols["tau"][3]) and np.isfinite(np.delete(cols["tau"], 3)).all()
    assert "column 'tau': 1 of 6 cells are not numbers (first: data row 3 from 0, 'abc')" in caplog.text


@pytest.mark.parametrize("sep", [";", "\t"])
def test_a_csv_with_semicolons_or_tabs_reads_like_one_with_commas(tmp_path, sep):
    path = tmp_path / "log.csv"
    path.write_text(sep.join(["t", "q", "label"]) + "\n" + "\n".join(sep.join([f"{i * 1e-3}", f"{0.1 * i}", "a"])
                                                                     for i in range(5)) + "\n")
    cols = read_table(path)
    assert set(cols) == {"t", "q"} and np.allclose(cols["q"], 0.1 * np.arange(5))


def test_decimal_commas_are_refused_naming_the_column(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("t;tau\n0;1,5\n0,001;2,25\n")
    with pytest.raises(IdentificationError, match="column 't' holds '0,001', a number with a decimal comma: expected "
                                                  "decimal points"):
        read_table(path)


@pytest.mark.parametrize(("header", "sep"), [('t;"tau, N m";q', ";"), ("t\tq (rad; joint 2)\ttau", "\t"),
                                             ("t\tq[rad,j2]\ttau", "\t"), ('t,"q; rad",tau', ",")])
def test_the_delimiter_is_the_one_that_splits_every_line_alike(tmp_path, header, sep):
    """A header whose column names hold another candidate delimiter (quoted, or in a tab file) reads by the
    delimiter that gives every line the same columns."""
    path = tmp_path / "log.csv"
    path.write_text(header + "\n" + "\n".join(sep.join(["0.001", "0.5", "2"]) for _ in range(4)) + "\n")
    assert len(read_table(path)) == 3


def test_a_text_column_with_commas_is_not_taken_for_decimal_commas(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("t;label;q\n0;a,b;0.5\n0.001;c,d;0.6\n")
    assert set(read_table(path)) == {"t", "q"}


def test_a_binary_file_named_csv_is_refused_without_echoing_it(tmp_path):
    path = tmp_path / "log.csv"
    junk = bytes(range(256)) * 20
    path.write_bytes(junk)
    with pytest.raises(IdentificationError, match=r"byte 128 is not UTF-8 text \(a binary file, or a Latin-1") as err:
        read_table(path)
    assert len(str(err.value)) < 300


def test_a_parquet_file_named_csv_is_told_to_be_renamed(tmp_path):
    path = write_table({"t": np.arange(3.0), "q": np.zeros(3)}, tmp_path / "log.parquet").rename(tmp_path / "log.csv")
    with pytest.raises(IdentificationError, match="a Parquet file .* named like a CSV table: expected the suffix "
                                                  r"\.parquet"):
        read_table(path)
