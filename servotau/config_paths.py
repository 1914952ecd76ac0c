"""Where config files are found: the packaged defaults, a process's config folder, references in a file.

The rules are in :mod:`servotau.config`'s docstring and README.md ("Configuration"); :mod:`servotau.config`
re-exports every name of this module.
"""

from __future__ import annotations

import logging
import sys
import types
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from .errors import ConfigError

DEFAULTS_PACKAGE = "servotau.defaults"
"""The package holding the default config files (the repository's ``config/``, mapped by pyproject.toml)."""

def default_config_dir() -> Path:
    """The folder of the packaged default config files (``config/`` in a checkout or an editable install).

    Raises:
        ConfigError: The package is not installed as files (e.g. imported from a zip archive).
    """
    folder = resources.files(DEFAULTS_PACKAGE)
    if not isinstance(folder, Path) or not folder.is_dir():
        raise ConfigError(f"{DEFAULTS_PACKAGE}: the default config is at {folder}: expected a folder on disk "
                          "(install servotau unzipped, e.g. with pip)")
    return folder


CONFIG_DIR: Path = default_config_dir()
"""The packaged default config folder (read-only in an installed wheel: ``servotau config init DIR``)."""
REPO_ROOT = Path(__file__).resolve().parent.parent
"""The checkout's root in a source checkout or an editable install (tests, benchmarks); not a config path."""


def describe_origin(p: Path) -> str:
    """`` (packaged default)`` for a file of the packaged defaults, else nothing (for the loaded-files lines)."""
    return " (packaged default)" if p.resolve().is_relative_to(CONFIG_DIR.resolve()) else ""


def resolve_config_path(path: str | Path, relative_to: str | Path | None = None) -> Path:
    """Find a config file.

    Args:
        path: The file. Absolute: read as given. Relative, with ``relative_to``: next to that file, else among
            the packaged defaults (:data:`CONFIG_DIR`), never in the working folder. Relative, without it (a
            path given explicitly): as given, else among the packaged defaults.
        relative_to: The config file that names ``path`` (a reference inside it), or None.

    Raises:
        ConfigError: Naming the path and every place looked.
    """
    p = Path(path)
    if p.is_absolute():
        if p.exists():
            return p
        raise ConfigError(f"{path}: config file not found")
    if relative_to is not None and Path(relative_to).is_file():
        places = [Path(relative_to).resolve().parent, CONFIG_DIR]
    elif relative_to is not None:  # a table not read from a file (from_mapping): the packaged defaults only
        places = [CONFIG_DIR]
    else:
        places = [Path("."), CONFIG_DIR]
    for place in places:
        candidate = p if place == Path(".") else place / p
        if candidate.exists():
            return candidate
    shown = ", ".join("the working folder" if place == Path(".") else str(place) for place in places)
    raise ConfigError(f"{path}: config file not found (looked in {shown})")


@dataclass(frozen=True)
class ConfigFiles:
    """Where a process finds its config files (chosen on its command line, passed down; no global state).

    Args:
        folder: The config folder (``--config DIR``), or None: the packaged defaults alone.
        given: File name (``"control.toml"``) -> the path given by that file's own flag (as given; a relative path
            that is not there but names a packaged default is that default).
        defaults: The packaged default folder.
    """

    folder: Path | None = None
    given: Mapping[str, Path] = field(default_factory=dict)
    defaults: Path = CONFIG_DIR

    @classmethod
    def create(cls, folder: str | Path | None = None,
               given: Mapping[str, tuple[str, str | Path | None]] | None = None) -> ConfigFiles:
        """Check and build: ``folder`` must be a folder; ``given`` maps a file name to ``(flag, path)`` (path
        None: not given), each path an existing file.

        Raises:
            ConfigError: Naming the flag and the folder or file, and what was expected.
        """
        if folder is not None:
            folder = Path(folder)
            if not folder.exists():
                raise ConfigError(f"--config {folder}: config folder not found: expected a config folder "
                                  "(servotau config init DIR writes one)")
            if not folder.is_dir():
                raise ConfigError(f"--config {folder}: not a folder: expected a config folder holding "
                                  "control.toml, hal.toml, ... (servotau config init DIR writes one)")
        files = {}
        for name, (flag, path) in (given or {}).items():
            if path is None:
                continue
            p = Path(path)
            if not p.exists() and not p.is_absolute() and (CONFIG_DIR / p).is_file():
                p = CONFIG_DIR / p  # a packaged default named by its name (--sim-config sim_identification.toml)
            if not p.exists():
                raise ConfigError(f"{flag} {p}: config file not found: expected a TOML config file ({name})")
            if not p.is_file():
                raise ConfigError(f"{flag} {p}: not a file: expected a TOML config file ({name})")
            files[name] = p
        return cls(folder, types.MappingProxyType(files))

    def path(self, name: str) -> Path:
        """The file ``name`` (e.g. ``"control.toml"``, ``"scenarios/hanging.toml"``): from its flag, else from the
        config folder, else the packaged default (absolute).

        Raises:
            ConfigError: Found in none of them.
        """
        if name in self.given:
            return self.given[name].absolute()
        places = ([self.folder] if self.folder is not None else []) + [self.defaults]
        for place in places:
            if (place / name).is_file():
                return (place / name).absolute()
        raise ConfigError(f"{name}: config file not found (looked in {', '.join(map(str, places))})")

    def describe(self) -> str:
        """One line: where this process's config files come from."""
        where = f"{self.folder}, then the packaged defaults" if self.folder is not None else "the packaged defaults"
        given = "".join(f", {name} = {p}" for name, p in self.given.items())
        return f"config folder: {where} ({self.defaults}){given}"


class LoadedFiles(logging.Filter):
    """Passes each ``config: FILE (...)`` line of the ``servotau.config`` logger once per process (a file read by
    several modules is named once)."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: set[str] = set()

    def filter(self, record: logging.LogRecord) -> bool:
        if record.name != "servotau.config":
            return True
        message = record.getMessage()
        if message in self.seen:
            return False
        self.seen.add(message)
        return True


class _Stderr(logging.Handler):
    """Writes to the ``sys.stderr`` of the moment (a test's capture as well as the terminal)."""

    def emit(self, record: logging.LogRecord) -> None:
        print(self.format(record), file=sys.stderr, flush=True)


def show_loaded_files() -> None:
    """Name every config file read on stderr, once each (the ``servotau.config`` logger at INFO, whatever the root
    logger's level). Called by each command's entry point; a second call (a second command run in the same
    process) names the files again."""
    logger = logging.getLogger("servotau.config")
    for h in logger.handlers:
        if isinstance(h, _Stderr):
            for f in h.filters:
                if isinstance(f, LoadedFiles):
                    f.seen.clear()
            return
    handler = _Stderr()
    handler.addFilter(LoadedFiles())
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False
