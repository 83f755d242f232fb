"""The docs' links lead somewhere, and no file points outside the repository.

Every relative link in README.md, CHANGELOG.md and docs/**/*.md (markdown links and images,
reference definitions, HTML ``<img src>`` and ``<a href>``) names a file or folder of the
checkout, and an anchor it names (``page.md#section``, ``#section``) is a heading of that page
under GitHub's rules, or an explicit ``<a id>``/``<a name>``. A link that works on one machine
only, because it climbs out of the checkout or names an absolute path there, fails for every
reader of a clone; so does a source file or script that cites such a path.
"""

import re
import unicodedata
from pathlib import Path
from urllib.parse import unquote

import pytest

ROOT = Path(__file__).resolve().parents[1]

PAGES = sorted([ROOT / "README.md", ROOT / "CHANGELOG.md", *(ROOT / "docs").rglob("*.md")])

# the text files a reader of the checkout gets: sources, docs, benchmarks and their records
SCANNED = [ROOT / name for name in ("README.md", "CHANGELOG.md", "pyproject.toml")] + [
    path for folder in ("src", "docs", "benchmarks", "scripts", "tests")
    for path in sorted((ROOT / folder).rglob("*"))
    if path.is_file() and "__pycache__" not in path.parts
    and path != Path(__file__).resolve()]  # this file's examples are such paths

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
CODE_SPAN = re.compile(r"(`+)((?:(?!\n[ \t]*\n).)+?)(?<!`)\1(?!`)", re.S)
INLINE = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*(<[^>\n]*>|[^)\s]+)"
                    r"(?:\s+\"[^\"]*\"|\s+'[^']*')?\s*\)")
REFERENCE = re.compile(r"^ {0,3}\[[^\]]+\]:\s*(<[^>\n]*>|\S+)", re.M)
HTML_LINK = re.compile(r"<(?:a|img|source)\b[^>]*?\b(?:href|src)\s*=\s*[\"']([^\"']*)[\"']", re.I)
HTML_ANCHOR = re.compile(r"<[a-z][^>]*?\b(?:id|name)\s*=\s*[\"']([^\"']+)[\"']", re.I)
ATX = re.compile(r"^ {0,3}#{1,6}(?:[ \t]+(.*?))?(?:[ \t]+#+)?[ \t]*$")
SCHEME = re.compile(r"^[a-z][a-z0-9+.-]*:", re.I)

# an absolute path on some machine, under /home, /work or /Users (not the tail of a URL)
MACHINE_PATH = re.compile(r"(?<![\w.~-])/(?:home|work|Users)/")
# a relative path that climbs, at the start of a token (not the ".../" of an ellipsis)
UPWARD = re.compile(r"(?<![\w./~-])((?:\.\./)+[\w.\-/]*)")


def _outside_fences(text: str) -> str:
    """The text with fenced code blocks blanked (lines kept, so line numbers hold)."""
    out, fence = [], None
    for line in text.splitlines():
        m = FENCE.match(line)
        if fence is None and m:
            fence = m.group(1)
            out.append("")
        elif fence is not None:
            if m and m.group(1)[0] == fence[0] and len(m.group(1)) >= len(fence) \
                    and not line.strip()[len(m.group(1)):].strip():
                fence = None
            out.append("")
        else:
            out.append(line)
    return "\n".join(out)


def _prose(text: str) -> str:
    """Markdown without code: fenced blocks and inline code spans blanked."""
    return CODE_SPAN.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), _outside_fences(text))


def slug(heading: str) -> str:
    """GitHub's anchor for a heading's text: its rendered text lower-cased, every character
    but letters, digits, marks, '-', '_' and spaces dropped, each space a hyphen."""
    parts = re.split(r"(`+[^`]*`+)", heading.strip())
    text = ""
    for part in parts:
        if part.startswith("`"):
            text += part.strip("`")
            continue
        part = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", part)  # a link shows its text
        part = re.sub(r"<[^>]+>", "", part)  # HTML tags show nothing
        part = re.sub(r"(?<!\w)_(.+?)_(?!\w)", r"\1", part)  # _emphasis_ shows its words
        text += part
    kept = "".join(c for c in text.strip().lower()
                   if c.isalnum() or c in "-_ " or unicodedata.category(c).startswith("M"))
    return kept.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Every anchor a page has: its headings' slugs (a repeated one gets -1, -2, ...) and the
    ids and names of its HTML elements."""
    text = page.read_text()
    found, seen = set(), set()
    for line in _outside_fences(text).splitlines():
        m = ATX.match(line)
        if not m:
            continue
        base = name = slug(m.group(1) or "")
        n = 0
        while name in seen:
            n += 1
            name = f"{base}-{n}"
        seen.add(name)
        found.add(name)
    found.update(HTML_ANCHOR.findall(_prose(text)))
    return found


def links(page: Path) -> list[tuple[int, str]]:
    """(line, target) of every link in a page's prose."""
    prose = _prose(page.read_text())
    out = []
    for pattern in (INLINE, REFERENCE, HTML_LINK):
        for m in pattern.finditer(prose):
            target = m.group(1).strip()
            if target.startswith("<") and target.endswith(">"):
                target = target[1:-1]
            out.append((prose.count("\n", 0, m.start()) + 1, target))
    return sorted(out)


def broken(page: Path, root: Path = ROOT) -> list[str]:
    """What is wrong with each relative link of a page, one line each."""
    problems = []
    for line, target in links(page):
        if not target or SCHEME.match(target):
            continue  # http(s), mailto and other absolute URLs are not checked
        path, _, anchor = target.partition("#")
        path = unquote(path)
        where = f"{page.relative_to(root)}:{line}: {target}"
        if path:
            dest = (root / path.lstrip("/")) if path.startswith("/") else (page.parent / path)
            dest = dest.resolve()
            if not dest.is_relative_to(root.resolve()):
                problems.append(f"{where}: outside the repository")
                continue
            if not dest.exists():
                problems.append(f"{where}: no such file")
                continue
        else:
            dest = page
        if anchor and dest.suffix == ".md" and unquote(anchor) not in anchors(dest):
            problems.append(f"{where}: no heading or anchor #{anchor} in {dest.name}")
    return problems


def outside_references(path: Path, root: Path = ROOT) -> list[str]:
    """Each place a text file names a path outside the repository: a machine's absolute path,
    or a ../ path that, read from the file's own folder, leaves the checkout or names nothing."""
    try:
        text = path.read_text()
    except (UnicodeDecodeError, OSError):
        return []  # not a text file
    found = []
    for number, line in enumerate(text.splitlines(), 1):
        where = f"{path.relative_to(root)}:{number}"
        for m in MACHINE_PATH.finditer(line):
            found.append(f"{where}: absolute path {line[m.start():].split()[0]!r}")
        for m in UPWARD.finditer(line):
            ref = m.group(1).rstrip(".")
            dest = (path.parent / ref).resolve()
            if not dest.is_relative_to(root.resolve()) or not dest.exists():
                found.append(f"{where}: {ref!r} names nothing in the repository")
    return found


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_resolve(page):
    assert broken(page) == []


def test_no_file_names_a_path_outside_the_repository():
    found = [problem for path in SCANNED for problem in outside_references(path)]
    assert found == []


def test_slugs_follow_github():
    assert slug("Set up and test") == "set-up-and-test"
    assert slug("pi0 / pi0.5 with openpi") == "pi0--pi05-with-openpi"
    assert slug("Training: `lerobot-train` on an rmbench dataset") == \
        "training-lerobot-train-on-an-rmbench-dataset"
    assert slug("The `no_memory` control") == "the-no_memory-control"
    assert slug("[Links](x.md) and <b>tags</b>") == "links-and-tags"


def test_a_broken_link_is_caught(tmp_path):
    """Each kind of wrong link is reported; right ones, URLs and code are not."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "other.md").write_text("# Other\n\n## Part\n\n## Part\n\n<a id=\"here\"></a>\n")
    page = tmp_path / "docs" / "page.md"
    page.write_text(
        "# Page\n\n"
        "[ok](other.md#part) [ok](other.md#part-1) [ok](other.md#here) [ok](#page)\n"
        "[ok](https://example.com/x) ![ok](other.md) <img src=\"other.md\"> [ok](../docs/)\n"
        "`[in code](missing.md)`\n\n"
        "```\n[in a block](missing.md)\n```\n\n"
        "[gone](missing.md) [up](../../x.md) [anchor](other.md#nope) <a href=\"#nope\">x</a>\n"
        "[ref]: gone.md\n")
    problems = broken(page, tmp_path)
    assert sorted(p.split(": ")[1] for p in problems) == sorted(
        ["missing.md", "../../x.md", "other.md#nope", "#nope", "gone.md"]), problems


def test_an_outside_path_is_caught(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("x\n")
    source = tmp_path / "docs" / "notes.py"
    source.write_text("# see ../README.md and ../NOTES.md, ../../up.md, /work/runs/x\n"
                      "# not paths: .../data/chunk-000, https://example.com/home/x\n")
    found = outside_references(source, tmp_path)
    assert len(found) == 3 and not any("README" in f for f in found), found
