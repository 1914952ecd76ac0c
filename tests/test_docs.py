"""Every code block of README.md and docs/*.md runs, parses, or says why it cannot.

- ```python blocks run in a subprocess, in a temporary directory, with a timeout.
- ```bash / ```sh / ```console blocks: each ``servotau ...`` command is parsed by the parser of
  ``servotau.cli`` (commands that need a running robot are parsed, not run); ``make T`` needs a target T in
  the Makefile; ``python -m servotau.hal ...`` needs each ``--flag`` in its ``--help``.
- ```toml blocks parse with tomllib; a ``[hal]`` table is checked by the HAL's config reader.
- A bare fence or ```text is prose (equations, usage synopses, output) and is not checked.
- Any other block, or one that cannot run, is marked by ``<!-- not runnable: reason -->`` on the line before
  its fence; every mark gives a reason.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
MARK = re.compile(r"<!--\s*not runnable:(.*?)-->")
FENCE = re.compile(r"^(\s*)```(\S*)\s*$")
SHELL = {"bash", "sh", "console", "shell"}
PROSE = {"", "text"}
PYTHON_TIMEOUT = 60.0  # [s] per block


@dataclass(frozen=True)
class Block:
    path: Path
    line: int  # 1-based line of the opening fence
    lang: str
    code: str
    mark: str | None  # the not-runnable reason, if marked

    @property
    def name(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def blocks(path: Path) -> list[Block]:
    """The fenced code blocks of ``path``, with the not-runnable mark just before each."""
    lines = path.read_text().splitlines()
    found, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        indent, lang = m.groups()
        j = i + 1
        while j < len(lines) and lines[j].strip() != "```":
            j += 1
        code = "\n".join(line[len(indent):] if line.startswith(indent) else line for line in lines[i + 1:j])
        prev = next((lines[k] for k in range(i - 1, -1, -1) if lines[k].strip()), "")
        mark = MARK.search(prev)
        found.append(Block(path, i + 1, lang.lower(), code + "\n", mark.group(1).strip() if mark else None))
        i = j + 1
    return found


ALL = [b for p in DOCS for b in blocks(p)]


def checked(langs: set[str]) -> list:
    return [pytest.param(b, id=b.name) for b in ALL if b.lang in langs and b.mark is None]


def test_docs_have_blocks():
    assert any(b.lang == "python" for b in ALL) and any(b.lang in SHELL for b in ALL)


@pytest.mark.parametrize("path", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_mark_has_a_reason_and_a_block(path: Path):
    lines = path.read_text().splitlines()
    for n, line in enumerate(lines):
        if "not runnable" not in line:
            continue
        m = MARK.search(line)
        assert m is not None and m.group(1).strip(), f"{path.name}:{n + 1}: write <!-- not runnable: reason -->"
        nxt = next((t for t in lines[n + 1:] if t.strip()), "")
        assert FENCE.match(nxt), f"{path.name}:{n + 1}: a not-runnable mark must stand just before a code fence"


def test_every_block_is_checked_or_marked():
    known = {"python", "toml", *SHELL, *PROSE}
    unmarked = [f"{b.name} ({b.lang})" for b in ALL if b.lang not in known and b.mark is None]
    assert not unmarked, f"no check for these blocks: mark them <!-- not runnable: reason -->: {unmarked}"


@pytest.mark.parametrize("block", checked({"python"}))
def test_python_block_runs(block: Block, tmp_path: Path):
    script = tmp_path / "block.py"
    script.write_text(block.code)
    r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True,
                       timeout=PYTHON_TIMEOUT)
    assert r.returncode == 0, f"{block.name} failed:\n{r.stderr[-3000:]}"


def commands(code: str) -> list[list[str]]:
    """The shell commands of a block: prompts and comments dropped, continuation lines joined."""
    out, pending = [], ""
    for raw in code.splitlines():
        line = raw.strip()
        if line.startswith("$ "):
            line = line[2:]
        if pending:
            line = pending + " " + line
            pending = ""
        if line.endswith("\\"):
            pending = line[:-1]
            continue
        words = shlex.split(line, comments=True)
        if words:
            out.append(words)
    return out


def make_targets() -> set[str]:
    text = (ROOT / "Makefile").read_text()
    return set(re.findall(r"^([A-Za-z][\w-]*):", text, flags=re.M))


def help_text(module: str) -> str:
    r = subprocess.run([sys.executable, "-m", module, "--help"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return r.stdout


@pytest.mark.parametrize("block", checked(SHELL))
def test_shell_block_parses(block: Block):
    from servotau.cli import COMMANDS, build_parser

    cmds = commands(block.code)
    assert cmds, f"{block.name}: an empty shell block"
    for words in cmds:
        if words[0] == "servotau":
            assert len(words) > 1 and words[1] in COMMANDS, f"{block.name}: {shlex.join(words)}: unknown command"
            try:
                build_parser(words[1]).parse_args(words[1:])
            except SystemExit as exc:
                pytest.fail(f"{block.name}: `{shlex.join(words)}` does not parse (exit {exc.code})")
        elif words[0] == "make":
            missing = set(words[1:]) - make_targets()
            assert not missing, f"{block.name}: no make target {sorted(missing)}"
        elif words[:3] == ["python", "-m", "servotau.hal"]:
            usage = help_text("servotau.hal")
            flags = [w.split("=")[0] for w in words[3:] if w.startswith("--")]
            assert all(f in usage for f in flags), f"{block.name}: {flags} not all in `python -m servotau.hal --help`"
        else:
            pytest.fail(f"{block.name}: `{shlex.join(words)}` has no check: mark the block "
                        "<!-- not runnable: reason -->")


@pytest.mark.parametrize("block", checked({"toml"}))
def test_toml_block_parses(block: Block):
    data = tomllib.loads(block.code)
    if "hal" in data:
        from servotau.config import Section
        from servotau.hal.registry import hal_section

        hal_section(Section(data, block.name, ""))
