"""Validated access to TOML configuration files.

A :class:`Section` is a view on one table of a config file that remembers the file and the dotted
path, so that every error names the file, the field and the expected value::

    ConfigError: config/servo.toml: field 'joints.RLEG_JOINT3.kp' = -5.0: expected a finite
    number > 0 [N m/rad]

Where files are found (docs in README.md, "Configuration"):

- The defaults ship inside the package (``servotau.defaults``: the repository's ``config/`` folder),
  found through importlib.resources: :data:`CONFIG_DIR`.
- A process reads the files of its config folder (``--config DIR``; :class:`ConfigFiles`): each file from
  its own flag if given, else from DIR, else the packaged default. A name the program chooses is never
  looked up in the working folder.
- A relative path written inside a config file (``motors = "motors/x.toml"``) is looked up next to that
  file, then among the packaged defaults (:func:`resolve_config_path` with ``relative_to``).
- A path given explicitly (a command-line flag, a caller's argument) is read as given; a relative one
  that does not exist there is looked up among the packaged defaults (``load_toml("control.toml")``).

Every file read is logged once at INFO on the ``servotau.config`` logger (the processes print it on
stderr), so no file is read silently.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import numbers
import sys
import tomllib
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from .config_paths import CONFIG_DIR, DEFAULTS_PACKAGE, REPO_ROOT, ConfigFiles, default_config_dir, describe_origin
from .config_paths import resolve_config_path as resolve_config_path
from .errors import ConfigError, ServotauError

__all__ = ["CONFIG_DIR", "DEFAULTS_PACKAGE", "REPO_ROOT", "ConfigFiles", "Section", "check_settings",
           "default_config_dir", "load_dataclass", "load_toml", "read_setting", "resolve_config_path", "setting"]

T = TypeVar("T")

log = logging.getLogger(__name__)

_MISSING = object()


def load_toml(path: str | Path, relative_to: str | Path | None = None) -> Section:
    """Parse a TOML file (found by :func:`resolve_config_path`) and return its root :class:`Section`; logs the
    file once at INFO on this module's logger.

    Raises:
        ConfigError: The file is missing, not a file, or not valid TOML (naming it).
    """
    p = resolve_config_path(path, relative_to)
    if p.is_dir():
        raise ConfigError(f"{p}: a folder: expected a TOML config file")
    try:
        with open(p, "rb") as f:
            data = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{p}: not valid TOML: {exc}") from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: cannot be read: {exc}") from exc
    log.info("config: read %s%s", p.resolve(), describe_origin(p))
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

    def missing(self, key: str, expected: str) -> ConfigError:
        """Build the error for the missing field ``key`` where ``expected`` was wanted."""
        return self.error(key, _MISSING, expected)

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


# -- dataclasses from TOML sections ------------------------------------------------------------------
# A config dataclass declares each field once, with its default, unit and bounds, by ``setting(...)``.
# ``load_dataclass`` reads a TOML section into it (errors name the file and the dotted field) and
# ``check_settings`` validates a directly built instance against the same metadata (errors of the
# caller's own type, e.g. ControlError), so no default or bound is written twice.

_SETTING = "servotau.setting"


@dataclass(frozen=True)
class _Spec:
    unit: str
    min: float | str | None
    max: float | str | None
    strict_min: bool
    choices: tuple[str, ...] | None
    shape: tuple[int, ...] | None = None

    def fixed(self) -> _Spec:
        """The spec without the bounds that name another field (checked once all fields are known)."""
        return dataclasses.replace(self, min=None if isinstance(self.min, str) else self.min,
                                   max=None if isinstance(self.max, str) else self.max)

    def relative(self, values: Mapping[str, Any]) -> tuple[_Spec, str] | None:
        """The spec with the bounds that name another field resolved from ``values``, and their text."""
        if not isinstance(self.min, str) and not isinstance(self.max, str):
            return None
        resolved, text = {}, {}
        for side in ("min", "max"):
            bound = getattr(self, side)
            if isinstance(bound, str):
                name, _, offset = bound.partition("+")
                value = values[name.strip()] + (float(offset) if offset else 0)
                resolved[side], text[side] = value, f"{bound.strip()} = {value:g}"
        spec = dataclasses.replace(self, **resolved)
        return spec, _expected("", spec, text).strip()


def setting(
    default: Any = _MISSING,
    *,
    unit: str = "",
    min: float | str | None = None,
    max: float | str | None = None,
    strict_min: bool = False,
    choices: Iterable[str] | None = None,
    shape: tuple[int, ...] | None = None,
    factory: Callable[[], Any] | None = None,
) -> Any:
    """A dataclass field whose default, unit ``[unit]`` and bounds the config loader reads.

    Args:
        default: The default value (immutable); omitted for a required field.
        unit: SI unit shown in error messages, e.g. ``"rad/s"``.
        min, max: Bounds of a number or of every element of a tuple or array of numbers; a string names
            another field, optionally plus a constant (``"order + 2"``, ``"hold_after"``).
        strict_min: The lower bound is strict (``> min``).
        choices: The allowed strings.
        shape: The shape of an ``np.ndarray`` field (read from nested lists of numbers).
        factory: Builds the default of a mutable field (an array), instead of ``default``.
    """
    spec = _Spec(unit, min, max, strict_min, tuple(choices) if choices is not None else None,
                 tuple(shape) if shape is not None else None)
    kwargs = {"default_factory": factory} if factory is not None else {} if default is _MISSING else \
        {"default": default}
    return dataclasses.field(metadata={_SETTING: spec}, **kwargs)


def _spec(f: dataclasses.Field) -> _Spec:
    return f.metadata.get(_SETTING) or _Spec("", None, None, False, None)


def _default(f: dataclasses.Field) -> Any:
    """The default of field ``f``, or ``_MISSING``."""
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return _MISSING


def _expected(kind: str, spec: _Spec, text: Mapping[str, str] | None = None) -> str:
    parts = [kind]
    if spec.choices is not None:
        return f"one of {list(spec.choices)}"
    text = text or {}
    if spec.min is not None:
        parts.append(f"{'>' if spec.strict_min else '>='} {text.get('min') or format(spec.min, 'g')}")
    if spec.max is not None:
        parts.append(f"<= {text.get('max') or format(spec.max, 'g')}")
    return " ".join(parts) + (f" [{spec.unit}]" if spec.unit else "")


def _number_ok(value: Any, spec: _Spec) -> bool:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
        return False
    if spec.min is not None and (value < spec.min or (spec.strict_min and value == spec.min)):
        return False
    return spec.max is None or value <= spec.max


def _convert(value: Any, tp: Any, spec: _Spec) -> tuple[Any, str | None]:
    """``value`` converted to the annotated type ``tp``, or ``(value, expected)`` when it does not fit."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (types.UnionType, typing.Union):
        if value is None and type(None) in args:
            return None, None
        (inner,) = [a for a in args if a is not type(None)]
        return _convert(value, inner, spec)
    if tp is float:
        return (float(value), None) if _number_ok(value, spec) else (value, _expected("a finite number", spec))
    if tp is int:
        ok = isinstance(value, numbers.Integral) and _number_ok(value, spec)
        return (int(value), None) if ok else (value, _expected("an integer", spec))
    if getattr(tp, "__module__", None) == "numpy" and getattr(tp, "__name__", None) == "ndarray":
        return _array(value, spec)
    if tp is bool:
        return (value, None) if isinstance(value, bool) else (value, "true or false")
    if tp is str:
        ok = isinstance(value, str) and (spec.choices is None or value in spec.choices)
        return (value, None) if ok else (value, _expected("a string", spec))
    if origin is tuple:
        variadic = len(args) == 2 and args[1] is Ellipsis
        item_tp = args[0]
        noun = {float: "finite numbers", int: "integers", str: "strings"}.get(item_tp, "values")
        kind = f"a list of {noun}" if variadic else f"a list of {len(args)} {noun}"
        expected = _expected(kind, spec) if spec.choices is None else f"a list of {noun} among {list(spec.choices)}"
        if not isinstance(value, (list, tuple)) or (not variadic and len(value) != len(args)):
            return value, expected
        out = []
        for v in value:
            conv, err = _convert(v, item_tp, spec)
            if err is not None:
                return value, expected
            out.append(conv)
        return tuple(out), None
    raise TypeError(f"setting type {tp!r} is not supported by the config loader")


def _array(value: Any, spec: _Spec) -> tuple[Any, str | None]:
    """An ``np.ndarray`` of floats of ``spec.shape`` (numpy is loaded: the field's annotation names it)."""
    np = sys.modules["numpy"]
    shape = spec.shape
    if shape is not None and len(shape) == 1:
        kind = f"a list of {shape[0]} finite numbers"
    elif shape is not None:
        kind = f"a {' x '.join(map(str, shape))} array of finite numbers"
    else:
        kind = "an array of finite numbers"
    expected = _expected(kind, spec)
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        return value, expected
    items = arr.ravel().tolist()
    if (shape is not None and arr.shape != shape) or any(not _number_ok(v, spec) for v in items) or \
            (not isinstance(value, np.ndarray) and _has_bool(value)):
        return value, expected
    return arr, None


def _has_bool(value: Any) -> bool:
    if isinstance(value, (list, tuple)):
        return any(_has_bool(v) for v in value)
    return isinstance(value, bool) or not isinstance(value, numbers.Real)


def _relative_bounds(fields: list[tuple[dataclasses.Field, Any]], values: Mapping[str, Any]
                     ) -> tuple[str, Any, str] | None:
    """The first field whose bound names another field and whose value is out of it:
    ``(name, value, expected)``, or None."""
    for f, tp in fields:
        rel = _spec(f).relative(values)
        if rel is None or values.get(f.name) is None:
            continue
        spec, text = rel
        kind = "an integer" if tp is int else "a finite number"
        if not _number_ok(values[f.name], spec):
            return f.name, values[f.name], f"{kind} {text}"
    return None


def _fields(cls: type) -> list[tuple[dataclasses.Field, Any]]:
    hints = typing.get_type_hints(cls)
    return [(f, hints[f.name]) for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_")]


def load_dataclass(cls: type[T], section: Section, *, ignore: Iterable[str] = (), base: Any = None,
                   **given: Any) -> T:
    """Build the config dataclass ``cls`` from a TOML section.

    Every field of ``cls`` declared with :func:`setting` (or typed as a config dataclass) is read from the
    key of the same name (the other fields are not config keys: the caller gives them, or they take their
    default), converted to its annotated type
    (float, int, bool, str, tuples of these, ``np.ndarray`` of a given ``shape``, ``X | None``, or a
    nested config dataclass read from a sub-table) and checked against its :func:`setting` bounds; a
    missing key takes the field's default, or the value of ``base`` (an instance of ``cls``) if given
    (a nested dataclass's missing keys take the values of the field's default instance). Unknown keys
    are refused, except ``ignore`` (keys another reader owns). ``given`` supplies fields the caller
    computes itself (they are not read from the file).

    Raises:
        ConfigError: Naming the file, the dotted field, the value and the expected value and unit.
    """
    fields = [(f, tp) for f, tp in _fields(cls) if _SETTING in f.metadata or dataclasses.is_dataclass(tp)]
    known = {f.name for f, _ in fields}
    section.check_keys(known | set(ignore))
    kwargs = dict(given)
    values = dict(given)  # every field's value, defaults included, for the bounds naming another field
    for f, tp in fields:
        if f.name in given:
            continue
        default = getattr(base, f.name) if base is not None else _default(f)
        if f.name not in section:
            if default is _MISSING:
                raise section.error(f.name, _MISSING, _expected("a value", _spec(f)))
            if base is not None:
                kwargs[f.name] = default
            values[f.name] = default
            continue
        if dataclasses.is_dataclass(tp):
            sub = default if isinstance(default, tp) else None
            kwargs[f.name] = values[f.name] = load_dataclass(tp, section.section(f.name), base=sub)
            continue
        value, expected = _convert(section.data[f.name], tp, _spec(f).fixed())
        if expected is not None:
            raise section.error(f.name, value, expected)
        kwargs[f.name] = values[f.name] = value
    bad = _relative_bounds(fields, values)
    if bad is not None:
        name, value, expected = bad
        raise section.error(name, section.data.get(name, value), expected)
    try:
        return cls(**kwargs)
    except ServotauError as exc:
        where = f" [{section.prefix}]" if section.prefix else ""
        raise ConfigError(f"{section.file}{where}: {exc}") from exc


def read_setting(cls: type, name: str, section: Section, key: str | None = None) -> Any:
    """One field ``name`` of the config dataclass ``cls`` read from ``key`` (default: ``name``) of a section
    whose layout differs from the dataclass's (the field's type, bounds, unit and default apply).

    Raises:
        ConfigError: Naming the file, the dotted key, the value and the expected value and unit.
    """
    key = key or name
    f, tp = dict((f.name, (f, tp)) for f, tp in _fields(cls))[name]
    if key not in section:
        default = _default(f)
        if default is _MISSING:
            raise section.error(key, _MISSING, _expected("a value", _spec(f)))
        return default
    value, expected = _convert(section.data[key], tp, _spec(f).fixed())
    if expected is not None:
        raise section.error(key, value, expected)
    return value


def check_settings(obj: Any, error: type[Exception] = ConfigError) -> None:
    """Validate a directly built config dataclass against its :func:`setting` metadata (in place:
    numbers become float or int, lists become tuples or arrays). Call it from ``__post_init__``; fields
    declared without :func:`setting` are left to the class's own checks.

    Raises:
        error: ``"<Class>.<field> = <value>: expected <what> [unit]"``.
    """
    fields = [(f, tp) for f, tp in _fields(type(obj)) if _SETTING in f.metadata]  # the others: the class's own
    for f, tp in fields:
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(tp):
            if not isinstance(value, tp):
                raise error(f"{type(obj).__name__}.{f.name} = {value!r}: expected a {tp.__name__}")
            continue
        conv, expected = _convert(value, tp, _spec(f).fixed())
        if expected is not None:
            raise error(f"{type(obj).__name__}.{f.name} = {_shown(value)}: expected {expected}")
        object.__setattr__(obj, f.name, conv)
    bad = _relative_bounds(fields, {f.name: getattr(obj, f.name) for f, _ in fields})
    if bad is not None:
        name, value, expected = bad
        raise error(f"{type(obj).__name__}.{name} = {value!r}: expected {expected}")


def _shown(value: Any) -> str:
    tolist = getattr(value, "tolist", None)  # an array is shown as its list
    return repr(tolist() if callable(tolist) and not isinstance(value, (int, float)) else value)
