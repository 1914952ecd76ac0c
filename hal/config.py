"""Helpers the HAL's config readers share: import strings, endpoint lists, command-line overrides.

The ``[hal]`` table itself (which backend, and the check of its sub-tables) is read by
:mod:`servotau.hal.registry`; each backend reads its own sub-table (:mod:`servotau.hal.backends`) and the
robot side reads ``[hal.server]`` and ``[hal.safety]`` (:mod:`servotau.hal.robot.config`).
"""

from __future__ import annotations

import importlib
from typing import Any

from servotau.config import Section

from .errors import HalError


def import_object(spec: str) -> Any:
    """The object named by an import string ``"package.module:attribute"`` (imported now)."""
    mod_name, sep, attr = spec.partition(":")
    if not sep or not mod_name or not attr:
        raise HalError(f"import string {spec!r}: expected 'package.module:attribute'")
    try:
        obj = importlib.import_module(mod_name)
    except ImportError as exc:
        raise HalError(f"import string {spec!r}: cannot import {mod_name}: {exc}") from exc
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise HalError(f"import string {spec!r}: {mod_name} has no attribute {attr!r}") from None
    return obj


def endpoint_list(s: Section, key: str, default: list[str]) -> list[str]:
    """The list of zenoh endpoints ``s[key]`` (``default`` if absent); ConfigError names the field."""
    value = s.data.get(key, default)
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise s.error(key, value, 'a list of zenoh endpoints, e.g. ["tcp/127.0.0.1:7447"]')
    return value


def with_override(s: Section, key: str, value: Any, flag: str) -> Section:
    """``s`` with ``key`` set to ``value`` by command-line option ``flag`` (errors then name the flag)."""
    return Section({**s.data, key: value}, f"{s.file} (with {flag})", s.prefix)
