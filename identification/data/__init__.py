"""The identification data layer, under both the paper's pipeline and the workbench.

- :mod:`.tables`: reading a log (:func:`open_log` for a servotau log, :func:`read_table` for any Parquet or
  CSV table), writing a table, the role of each column (:func:`resolve_roles`).
- :mod:`.segments`: contiguous segments of a log (:func:`segments`) and the shift of a signal (:func:`shift`).
- :mod:`.folds`: held-out data, the pipeline's :func:`holdout_split` and the workbench's :func:`blocked_folds`.
- :mod:`.aligned`: a log's estimated and aligned samples per joint (:func:`load_aligned`).

Where the two paths did the same thing differently, the shared function takes the difference as a parameter
and each caller keeps its own result (docs/identification.md, "The data layer").
"""

from .aligned import MIN_SECONDS, AlignedLog, JointSamples, load_aligned
from .folds import DEFAULT_FOLDS, GUARD_S, Fold, blocked_folds, folds_of, holdout_split, time_blocks
from .segments import segments, shift
from .tables import ROLES, open_log, read_table, resolve_roles, servotau_joints, table_columns, write_table

__all__ = [
    "DEFAULT_FOLDS",
    "GUARD_S",
    "MIN_SECONDS",
    "ROLES",
    "AlignedLog",
    "Fold",
    "JointSamples",
    "blocked_folds",
    "folds_of",
    "holdout_split",
    "load_aligned",
    "open_log",
    "read_table",
    "resolve_roles",
    "segments",
    "servotau_joints",
    "shift",
    "table_columns",
    "time_blocks",
    "write_table",
]
