"""The documentation stays short, linked and reproducible.

- README.md is the ten-minute reference: at most ``README_MAX_LINES`` lines.
- Every relative link and image in README.md, CHANGELOG.md and docs/**/*.md names a file that exists
  (``#anchors`` stripped; an anchor into the same file names one of its headings).
- Every markdown table in README.md and docs/ (not docs/decisions/ or CHANGELOG.md, which are history)
  names the command that prints it, in a code span within ``COMMAND_WINDOW`` lines above it, and that
  command exists:
  a ``python -m X`` module is importable, a ``pytest path`` or ``tests/...py`` file is there, a
  ``make T`` target is in the Makefile, a ``ulnef X`` subcommand is in ``service/cli.py``. A table
  that is not a result (settings, a file map) carries ``<!-- not a result -->`` right above it.
- No tracked file refers to the team's notes outside the repository.

Each check is a function of the text, so the last tests feed it broken markdown and see it fail.
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README_MAX_LINES = 400
COMMAND_WINDOW = 8
NOT_A_RESULT = "<!-- not a result -->"
HISTORY = ("docs/decisions/", "CHANGELOG.md")
# Built from pieces so that this file does not hold them itself.
OUTSIDE = ("DESIGN" + ".md", "../" + "shared")

FENCE = re.compile(r"^\s*(```|~~~)")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
COMMANDS = re.compile(
    r"python -m (?P<module>[\w.]+)"
    r"|pytest(?: -\w+)* (?P<pytest>[\w/.-]+)"
    r"|(?<![\w/.])(?P<testfile>tests/[\w/.-]+\.py)"
    r"|\bmake (?P<make>[\w-]+)"
    r"|\bulnef (?P<ulnef>[a-z][\w-]*)"
)


def markdown_files() -> list[Path]:
    files = [REPO / "README.md", REPO / "CHANGELOG.md", *sorted((REPO / "docs").rglob("*.md"))]
    return [p for p in files if p.is_file()]


def rel(path: Path) -> str:
    return path.relative_to(REPO).as_posix()


def without_code(text: str) -> str:
    """The text with fenced blocks blanked (lines kept, so line numbers hold) and inline code removed."""
    out, fenced = [], False
    for line in text.splitlines():
        if FENCE.match(line):
            fenced = not fenced
            out.append("")
            continue
        out.append("" if fenced else re.sub(r"`[^`]*`", "", line))
    return "\n".join(out)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(text: str) -> set[str]:
    return {slug(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.*)$", without_code(text), flags=re.M)}


def broken_links(path: Path, text: str) -> list[str]:
    """``file:line: target`` of every relative link or image in ``text`` (of ``path``) that resolves
    to nothing."""
    broken = []
    for n, line in enumerate(without_code(text).splitlines(), 1):
        for target in LINK.findall(line):
            if re.match(r"^(https?:|mailto:)", target):
                continue
            file, _, anchor = target.partition("#")
            if not file:
                if anchor not in anchors(text):
                    broken.append(f"{rel(path)}:{n}: {target}")
                continue
            if not (path.parent / file).exists():
                broken.append(f"{rel(path)}:{n}: {target}")
    return broken


def tables(text: str) -> list[int]:
    """0-based line numbers of each markdown table's header (a ``|`` row followed by a ``|---`` row),
    in or out of code fences (a benchmark's printed table is a table)."""
    lines = text.splitlines()
    out = []
    for i in range(len(lines) - 1):
        header, rule = lines[i].strip(), lines[i + 1].strip()
        if header.startswith("|") and re.match(r"^\|\s*:?-{3,}", rule):
            if i == 0 or not lines[i - 1].strip().startswith("|"):
                out.append(i)
    return out


def make_targets() -> set[str]:
    return set(re.findall(r"^([\w-]+):", (REPO / "Makefile").read_text(), flags=re.M))


def cli_commands() -> set[str]:
    source = (REPO / "service" / "cli.py").read_text()
    return set(re.findall(r"add_parser\(\s*\"([\w-]+)\"", source))


def command_problems(command_lines: list[str]) -> tuple[bool, list[str]]:
    """(whether the lines name a command in a code span, what is wrong with the commands they name)."""
    found, problems = False, []
    spans = [span for line in command_lines for span in re.findall(r"`([^`]+)`", line)]
    for span in spans:
        for m in COMMANDS.finditer(span):
            found = True
            if m.group("module"):
                module = m.group("module").rstrip(".")
                try:
                    spec = importlib.util.find_spec(module)
                except ModuleNotFoundError:
                    spec = None
                if spec is None:
                    problems.append(f"no module {module}")
            elif m.group("pytest") or m.group("testfile"):
                path = (m.group("pytest") or m.group("testfile")).split("::")[0].rstrip(".")
                if not (REPO / path).exists():
                    problems.append(f"no test file {path}")
            elif m.group("make") and m.group("make") not in make_targets():
                problems.append(f"no make target {m.group('make')}")
            elif m.group("ulnef") and m.group("ulnef") not in cli_commands():
                problems.append(f"no ulnef command {m.group('ulnef')}")
    return found, problems


def unsourced_tables(path: Path, text: str) -> list[str]:
    """``file:line: why`` of every table with no command above it, or a command that does not exist."""
    lines = text.splitlines()
    out = []
    for i in tables(text):
        above = lines[max(0, i - COMMAND_WINDOW) : i]
        nearest = next((line.strip() for line in reversed(above) if line.strip()), "")
        if nearest == NOT_A_RESULT:
            continue
        found, problems = command_problems(above)
        if not found:
            out.append(f"{rel(path)}:{i + 1}: no command within {COMMAND_WINDOW} lines above the table")
        out += [f"{rel(path)}:{i + 1}: {p}" for p in problems]
    return out


def test_the_readme_reads_in_ten_minutes():
    lines = (REPO / "README.md").read_text().splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines (at most {README_MAX_LINES})"


@pytest.mark.parametrize("path", markdown_files(), ids=rel)
def test_every_relative_link_resolves(path: Path):
    assert broken_links(path, path.read_text()) == []


@pytest.mark.parametrize("path", [p for p in markdown_files() if not rel(p).startswith(HISTORY)], ids=rel)
def test_every_table_names_the_command_that_prints_it(path: Path):
    assert unsourced_tables(path, path.read_text()) == []


def test_the_documents_have_tables_to_check():
    """The table test is not vacuous: the README and docs/benchmarks.md carry result tables."""
    for name in ("README.md", "docs/benchmarks.md"):
        assert len(tables((REPO / name).read_text())) >= 3, name


def test_design_sections_the_code_cites_exist():
    """The code cites ``docs/design.md section N``: each N cited is a ``## N. Title`` heading there."""
    design = (REPO / "docs" / "design.md").read_text()
    numbers = set(re.findall(r"^## (\d+)\. \S", design, flags=re.M))
    cited = set()
    for folder in ("service", "training", "export", "benchmarks", "tests"):
        for source in (REPO / folder).rglob("*.py"):
            cited |= set(re.findall(r"design\.md section (\d+)", source.read_text(errors="replace")))
    assert cited, "no code cites docs/design.md"
    assert cited <= numbers, f"cited but missing: {sorted(cited - numbers)}"
    assert numbers >= {str(n) for n in range(1, 8)}


def tracked_text_files() -> list[Path]:
    try:
        names = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("not a git checkout")
    paths = {REPO / n for n in names.decode().split("\0") if n} | set(markdown_files())
    out = []
    for p in sorted(paths):
        if p.is_file() and p != Path(__file__).resolve():
            head = p.read_bytes()[:4096]
            if b"\0" not in head:
                out.append(p)
    return out


def outside_references(name: str, text: str) -> list[str]:
    return [f"{name}:{n}: {word}" for n, line in enumerate(text.splitlines(), 1)
            for word in OUTSIDE if word in line]  # fmt: skip


def test_no_file_refers_to_notes_outside_the_repository():
    found = []
    for p in tracked_text_files():
        found += outside_references(rel(p), p.read_text(errors="replace"))
    assert found == []


# The checks themselves fail on broken markdown.


def test_a_broken_link_is_found():
    page = REPO / "docs" / "page.md"
    text = "# Title\n[ok](../README.md) [anchor](#title) ![img](images/none.png) [gone](#nowhere)\n"
    text += "`[in code](nowhere.md)`\n```\n[fenced](nowhere.md)\n```\n[web](https://example.com)\n"
    assert broken_links(page, text) == ["docs/page.md:2: images/none.png", "docs/page.md:2: #nowhere"]


def test_a_table_without_a_command_is_found():
    page = REPO / "docs" / "page.md"
    table = "| a | b |\n|---|---:|\n| 1 | 2 |\n"
    assert unsourced_tables(page, "Some words.\n\n" + table) == [
        f"docs/page.md:3: no command within {COMMAND_WINDOW} lines above the table"]
    assert unsourced_tables(page, f"{NOT_A_RESULT}\n" + table) == []
    fenced = "`python -m benchmarks.outfits --bodies 3`:\n\n```\n" + table + "```\n"
    assert unsourced_tables(page, fenced) == []
    assert unsourced_tables(page, "`python -m benchmarks.nothing_here`:\n" + table) == [
        "docs/page.md:2: no module benchmarks.nothing_here"]
    assert unsourced_tables(page, "`make nothing-here`, `pytest tests/nothing.py`:\n" + table) == [
        "docs/page.md:2: no make target nothing-here", "docs/page.md:2: no test file tests/nothing.py"]
    far = "`python -m benchmarks.outfits`\n" + "words\n" * COMMAND_WINDOW + table
    assert len(unsourced_tables(page, far)) == 1


def test_a_reference_outside_the_repository_is_found():
    text = "fine\nsee " + OUTSIDE[1] + "/notes and " + OUTSIDE[0] + "\n"
    assert outside_references("page.md", text) == [f"page.md:2: {OUTSIDE[0]}", f"page.md:2: {OUTSIDE[1]}"]
