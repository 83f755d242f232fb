"""Every command the docs show says which environment it runs in.

rmbench installs into `.venv/` and LeRobot into an environment of its own, so a bare
``rmbench``, ``pip`` or ``python`` in a command block runs whatever the reader's shell finds
first: another install, or nothing. Each command in a ``bash`` block of README.md or
docs/**/*.md therefore names its environment (``.venv/bin/rmbench``,
``.venv-lerobot/bin/lerobot-train``), is a shell built-in or a command that needs none
(``bash scripts/install.sh``), or comes after the page activated an environment
(``source .venv/bin/activate``).
"""

import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})\s*(\w*)")
ASSIGNMENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*=")
ACTIVATE = re.compile(r"^(?:source|\.)\s+\S*\.venv[\w-]*/bin/activate\b")
# commands that need no Python environment of ours: the shell's, the installers', venv's maker
NEUTRAL = {"bash", "sh", "source", ".", "cd", "export", "mkdir", "apt-get", "git", "python3.11"}


def commands(page: Path) -> list[tuple[int, str]]:
    """(line, command) of each logical line of the page's bash blocks, continuations joined."""
    out, fence, pending, start = [], None, "", 0
    for number, line in enumerate(page.read_text().splitlines(), 1):
        m = FENCE.match(line)
        if fence is None:
            if m:
                fence = (m.group(1), m.group(2))
            continue
        if m and m.group(1)[0] == fence[0][0] and len(m.group(1)) >= len(fence[0]) and not m.group(2):
            fence = None
            continue
        if fence[1] not in ("bash", "sh", "shell", "console"):
            continue
        text = line.strip()
        if not pending:
            start = number
        if text.endswith("\\"):
            pending += text[:-1] + " "
            continue
        text = pending + text
        pending = ""
        if text and not text.startswith("#"):
            out.append((start, text))
    return out


def substitutions(command: str) -> tuple[str, list[str]]:
    """The command with each ``$(...)`` replaced by a word, and the commands inside them."""
    outer, inner, i, quote = [], [], 0, None
    while i < len(command):
        c = command[i]
        if quote == "'":
            quote = None if c == "'" else quote
        elif c == "\\":
            outer.append(command[i:i + 2])
            i += 2
            continue
        elif command.startswith("$(", i):
            depth, j, q = 1, i + 2, None
            while j < len(command) and depth:
                d = command[j]
                if q:
                    q = None if d == q else q
                elif d in "'\"":
                    q = d
                else:
                    depth += {"(": 1, ")": -1}.get(d, 0)
                j += 1
            inner.append(command[i + 2:j - 1])
            outer.append("SUBSTITUTION")
            i = j
            continue
        elif c == '"':
            quote = None if quote == '"' else '"'
        elif c == "'" and quote is None:
            quote = "'"
        outer.append(c)
        i += 1
    return "".join(outer), inner


def programs(command: str) -> list[str]:
    """The program each simple command of a command line starts (env assignments skipped),
    those inside its ``$(...)`` included."""
    outer, inner = substitutions(command)
    lexer = shlex.shlex(outer, posix=True, punctuation_chars=";&|")
    lexer.whitespace_split = True
    found, at_start = [], True
    for token in lexer:
        if token in ("&&", "||", ";", "&"):
            at_start = True
        elif at_start and not ASSIGNMENT.match(token):
            found.append(token)
            at_start = False
    return found + [program for part in inner for program in programs(part)]


def unnamed(page: Path, root: Path = ROOT) -> list[str]:
    """Each command of a page that runs a program without naming its environment."""
    problems, activated = [], False
    for line, command in commands(page):
        if ACTIVATE.match(command):
            activated = True
        if activated:
            continue
        for program in programs(command):
            if program in NEUTRAL or re.match(r"^\.venv[\w-]*/bin/", program):
                continue
            problems.append(f"{page.relative_to(root)}:{line}: {program!r} in: {command}")
    return problems


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_commands_name_their_environment(page):
    assert unnamed(page) == []


def test_a_bare_command_is_caught(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(
        "```bash\n"
        "bash scripts/install.sh && .venv/bin/rmbench quickstart\n"
        "HF_HUB_OFFLINE=1 .venv-lerobot/bin/lerobot-train --steps=5 \\\n"
        "    --policy.type=act   # a comment\n"
        "rmbench eval --task x --out y\n"
        "X=$(python -c 'import json; print(1)')\n"
        "```\n\n"
        "```python\nimport rmbench\n```\n\n"
        "```bash\nsource .venv/bin/activate\nrmbench tasks\n```\n")
    assert [p.split(": ")[1] for p in unnamed(page, tmp_path)] == ["'rmbench' in", "'python' in"]
