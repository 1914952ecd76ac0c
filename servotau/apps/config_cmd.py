"""servotau config: the default config files, copied into a folder to edit.

    servotau config init DIR [--force]   copy every default file (control.toml, hal.toml, motors/, scenarios/,
                                         tasks/, ...) into DIR; then run any command with --config DIR
    servotau config path                 print the folder of the packaged defaults (read-only)

A command run with --config DIR reads each file from DIR, else from the packaged defaults, and names every
file it reads on stderr. init refuses to overwrite a file that exists unless --force.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from servotau.config import CONFIG_DIR
from servotau.errors import ConfigError

PATTERNS = ("*.toml", "*.csv")
"""The files of the config folder that are copied (not the package's own __init__.py)."""


def register(sub) -> None:
    p = sub.add_parser("config", help="copy the default config files into a folder to edit (config init DIR)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    cmds = p.add_subparsers(dest="config_command", required=True, metavar="STEP")
    init = cmds.add_parser("init", help="copy the packaged default config files into DIR")
    init.add_argument("dir", metavar="DIR", help="folder to write (created if missing)")
    init.add_argument("--force", action="store_true", help="overwrite files that exist in DIR")
    init.set_defaults(func=init_main)
    path = cmds.add_parser("path", help="print the folder of the packaged default config files")
    path.set_defaults(func=lambda _args: print(CONFIG_DIR) or 0)


def default_files(source: Path = CONFIG_DIR) -> list[Path]:
    """The default config files, relative to ``source``, sorted."""
    return sorted({p.relative_to(source) for pattern in PATTERNS for p in source.rglob(pattern)
                   if "__pycache__" not in p.parts})


def init(folder: str | Path, *, force: bool = False, source: Path = CONFIG_DIR) -> list[Path]:
    """Copy the default config files into ``folder`` (sub-folders kept); return the files written.

    Raises:
        ConfigError: ``folder`` is a file, or a file exists there and ``force`` is false (nothing is written).
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{folder}: not a folder: expected a folder to write the config files into")
    files = default_files(source)
    existing = [f for f in files if (folder / f).exists()]
    if existing and not force:
        shown = ", ".join(str(folder / f) for f in existing[:3]) + (" ..." if len(existing) > 3 else "")
        raise ConfigError(f"{folder}: {len(existing)} config files exist already ({shown}): expected a new or empty "
                          "folder, or --force to overwrite them")
    written = []
    for f in files:
        target = folder / f
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source / f, target)
        written.append(target)
    return written


def init_main(args) -> int:
    written = init(args.dir, force=args.force)
    print(f"wrote {len(written)} config files into {args.dir} (from {CONFIG_DIR}); use them with --config {args.dir}",
          file=sys.stderr)
    for f in written:
        print(f)
    return 0
