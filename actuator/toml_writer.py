"""TOML text for the files the project writes (the motor file, :mod:`.motor_file`; the controller's F/T offsets):
tomllib reads TOML, tomli-w writes it.

Adds what tomli-w leaves to the caller: comment lines at the top, and the refusal of NaN and infinity (TOML
can write them, a motor parameter must never be one).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import tomli_w


def dumps(data: Mapping[str, object], header: Sequence[str] = ()) -> str:
    """``data`` as TOML text (tables for nested mappings), after ``header``'s lines as ``# `` comments.

    Raises:
        ValueError: A float of ``data`` is NaN or infinite (naming its dotted key).
        TypeError: A value TOML cannot hold.
    """
    _check_finite(data, "")
    return "".join(f"# {line}\n" for line in header) + tomli_w.dumps(data)


def _check_finite(data: Mapping[str, object], prefix: str) -> None:
    for k, v in data.items():
        name = f"{prefix}{k}"
        if isinstance(v, Mapping):
            _check_finite(v, name + ".")
        elif isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"cannot write non-finite float {name} = {v!r}: expected a finite number")
