"""Validated access to TOML configuration files.

A :class:`Section` is a view on one table of a config file that remembers the file and the dotted
path, so that every error names the file, the field and the expected value::

    ConfigError: config/servo.toml: field 'joints.RLEG_JOINT3.kp' = -5.0: expected a finite
    number > 0 [N m/rad]
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .errors import ConfigError

REPO_ROOT = Path(__file__).resolve().parent.parent
CONFIG_DIR = REPO_ROOT / "config"

_MISSING = object()


def resolve_config_path(path: str | Path) -> Path:
    """Find a config file: as given, else relative to the repository's ``config/`` folder."""
    p = Path(path)
    if p.exists():
        return p
    alt = CONFIG_DIR / p
    if alt.exists():
        return alt
    raise ConfigError(f"{path}: config file not found (looked in . and {CONFIG_DIR})")


def load_toml(path: str | Path) -> Section:
    """Parse a TOML file and return its root :class:`Section`."""
    p = resolve_config_path(path)
    try:
        with open(p, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML: {exc}") from exc
    return Section(data, str(p), "")


@dataclass(frozen=True)
class Section:
    """A table of a config file, with the file name and dotted path kept for error messages."""

    data: Mapping[str, Any]
    file: str
    prefix: str

    def _name(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def error(self, key: str, value: Any, expected: str) -> ConfigError:
        """Build the error for field ``key`` holding ``value`` where ``expected`` was wanted."""
        shown = "missing" if value is _MISSING else f"= {value!r}"
        return ConfigError(f"{self.file}: field '{self._name(key)}' {shown}: expected {expected}")

    def __contains__(self, key: str) -> bool:
        return key in self.data

    def keys(self) -> list[str]:
        return list(self.data.keys())

    def _raw(self, key: str, default: Any, expected: str) -> Any:
        value = self.data.get(key, _MISSING)
        if value is _MISSING:
            if default is _MISSING:
                raise self.error(key, _MISSING, expected)
            return default
        return value

    def float(
        self,
        key: str,
        default: Any = _MISSING,
        *,
        min: float | None = None,
        max: float | None = None,
        strict_min: bool = False,
        unit: str = "",
    ) -> float:
        """A finite number within optional bounds (``strict_min`` makes the lower bound strict)."""
        op = ">" if strict_min else ">="
        parts = ["a finite number"]
        if min is not None:
            parts.append(f"{op} {min:g}")
        if max is not None:
            parts.append(f"<= {max:g}")
        expected = " ".join(parts) + (f" [{unit}]" if unit else "")
        value = self._raw(key, default, expected)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.error(key, value, expected)
        value = float(value)
        if min is not None and (value < min or (strict_min and value == min)):
            raise self.error(key, value, expected)
        if max is not None and value > max:
            raise self.error(key, value, expected)
        return value

    def int(self, key: str, default: Any = _MISSING, *, min: int | None = None, max: int | None = None) -> int:
        """An integer within optional bounds."""
        expected = "an integer" + (f" >= {min}" if min is not None else "") + (
            f" <= {max}" if max is not None else ""
        )
        value = self._raw(key, default, expected)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, value, expected)
        if (min is not None and value < min) or (max is not None and value > max):
            raise self.error(key, value, expected)
        return value

    def bool(self, key: str, default: Any = _MISSING) -> bool:
        value = self._raw(key, default, "true or false")
        if not isinstance(value, bool):
            raise self.error(key, value, "true or false")
        return value

    def str(self, key: str, default: Any = _MISSING, *, choices: Iterable[str] | None = None) -> str:
        """A string, optionally one of ``choices``."""
        choices = list(choices) if choices is not None else None
        expected = f"one of {choices}" if choices else "a string"
        value = self._raw(key, default, expected)
        if not isinstance(value, str) or (choices is not None and value not in choices):
            raise self.error(key, value, expected)
        return value

    def floats(self, key: str, length: int | None = None, default: Any = _MISSING, *, unit: str = "") -> list:
        """A list of finite numbers, of the given length if any."""
        expected = (f"a list of {length} finite numbers" if length else "a list of finite numbers") + (
            f" [{unit}]" if unit else ""
        )
        value = self._raw(key, default, expected)
        if not isinstance(value, (list, tuple)) or (length is not None and len(value) != length):
            raise self.error(key, value, expected)
        for v in value:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise self.error(key, value, expected)
        return [float(v) for v in value]

    def section(self, key: str, default: Any = _MISSING) -> Section:
        """A sub-table (``default={}`` makes it optional)."""
        value = self._raw(key, default, "a table")
        if not isinstance(value, Mapping):
            raise self.error(key, value, "a table")
        return Section(value, self.file, self._name(key))

    def check_keys(self, allowed: Iterable[str]) -> None:
        """Reject unknown fields (typos must not be silently ignored)."""
        allowed = sorted(set(allowed))
        for key in self.data:
            if key not in allowed:
                raise self.error(key, self.data[key], f"a known field, one of {allowed}")
