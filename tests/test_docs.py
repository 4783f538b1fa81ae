"""The documentation stays inside the repository and whole: no file under gbviewer/, native/, shaders/, docs/ or the
README refers to a path outside the repository or to a tracker number, every relative link of the README and
docs/*.md reaches an existing file and, with a #fragment, an existing heading (GitHub's anchors), and every gbviewer
import of their Python examples resolves."""

from __future__ import annotations

import importlib
import re
import unicodedata
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CHECKED = ("gbviewer", "native", "shaders", "docs")
SUFFIXES = {".py", ".h", ".cpp", ".cu", ".glsl", ".comp", ".md", ".txt", ".cmake", ".toml", ".sh"}
OUTSIDE = re.compile(r"\.\./shared|(?<![\w.])/work/|\bshared/(?:scenes|papers|hooks)\b|\bKERNELS\.md\b|\bDESIGN\.md\b")
TRACKER = re.compile(r"\bissues? #?\d+", re.IGNORECASE)
LINK = re.compile(r"(?<!\\)\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def checked_files() -> list[Path]:
    files = [REPO / "README.md"]
    for top in CHECKED:
        files += [p for p in sorted((REPO / top).rglob("*")) if p.is_file() and p.suffix in SUFFIXES]
    return files


def offences(text: str) -> list[str]:
    """The references to outside paths and tracker numbers in `text`, one 'line N: ...' each."""
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        for pattern, what in ((OUTSIDE, "a path outside the repository"), (TRACKER, "a tracker number")):
            for m in pattern.finditer(line):
                out.append(f"line {n}: {what}: {m.group(0)!r}")
    return out


def test_offences_are_found():
    """The patterns catch what they are for and leave code and public references alone."""
    bad = [
        "see ../shared/KERNELS.md §6.3",
        "(KERNELS.md §8.1)",
        "DESIGN.md says",
        "/work/shared/scenes/x.ply",
        "Level of detail (issue 24)",
        "as issues 18 and 29 found",
        "Issue #7",
    ]
    good = [
        "docs/modes.md#gaussian-blending",
        "gsplat PR #1036",
        "x = a[#i]",
        "see bench/RESULTS.md",
        "#define X 1",
        "#include <cstdint>",
        "label `step 3/76: #12`",
        "shared_stage",
        "the shared headers",
    ]
    assert all(offences(s) for s in bad), [s for s in bad if not offences(s)]
    assert not any(offences(s) for s in good), [offences(s) for s in good if offences(s)]


@pytest.mark.parametrize("path", checked_files(), ids=lambda p: str(p.relative_to(REPO)))
def test_no_outside_paths_or_tracker_numbers(path: Path):
    found = offences(path.read_text(errors="replace"))
    assert not found, f"{path.relative_to(REPO)}: " + "; ".join(found)


def github_anchor(heading: str) -> str:
    """GitHub's anchor of a markdown heading: lower case, punctuation but '-' and '_' dropped, spaces to '-'."""
    text = re.sub(r"`|\*\*|\*", "", heading.strip()).lower()
    text = "".join(c for c in text if c in " -_" or unicodedata.category(c)[0] in "LN")
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading's anchor in a markdown file (repeated headings get -1, -2, ... as on GitHub)."""
    seen: dict[str, int] = {}
    out = set()
    fenced = False
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
        m = None if fenced else re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            base = github_anchor(m.group(1))
            k = seen.get(base, 0)
            seen[base] = k + 1
            out.add(base if k == 0 else f"{base}-{k}")
    return out


def links(path: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    return [t for t in LINK.findall(text) if not re.match(r"[a-z]+:", t)]


def test_anchors_follow_github():
    assert github_anchor("Flicker (temporal stability)") == "flicker-temporal-stability"
    assert github_anchor("`stochastic_popfree`") == "stochastic_popfree"
    assert github_anchor("Google Highway (the vector paths)") == "google-highway-the-vector-paths"
    assert github_anchor("Culling, radius, tiles") == "culling-radius-tiles"


def test_links_are_found():
    sample = REPO / "docs" / "modes.md"
    assert any(t.startswith("architecture.md") for t in links(sample))
    assert "gaussian-blending" in anchors(sample)


def broken_links(doc: Path) -> list[str]:
    """The relative links of `doc` whose file or heading anchor does not exist."""
    broken = []
    for target in links(doc):
        file, _, fragment = target.partition("#")
        dest = (doc.parent / file).resolve() if file else doc
        if not dest.exists():
            broken.append(f"{target}: no such file")
        elif fragment and dest.suffix == ".md" and fragment not in anchors(dest):
            broken.append(f"{target}: no heading with that anchor in {dest.name}")
    return broken


def test_broken_links_are_found(tmp_path: Path):
    (tmp_path / "a.md").write_text(
        "# Title\n\n## Two words\n\n[ok](#two-words) [ok](b.md#b) [x](c.md) [y](b.md#nope) "
        "[z](#title-2) [web](https://example.com)\n\n```\n[not a link](d.md)\n```\n"
    )
    (tmp_path / "b.md").write_text("# B\n")
    assert broken_links(tmp_path / "a.md") == [
        "c.md: no such file",
        "b.md#nope: no heading with that anchor in b.md",
        "#title-2: no heading with that anchor in a.md",
    ]


@pytest.mark.parametrize(
    "doc", [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))], ids=lambda p: str(p.relative_to(REPO))
)
def test_relative_links_resolve(doc: Path):
    broken = broken_links(doc)
    assert not broken, f"{doc.relative_to(REPO)}: " + "; ".join(broken)


PYTHON_BLOCK = re.compile(r"```python\n(.*?)```", re.S)
IMPORT = re.compile(r"^\s*from (gbviewer[\w.]*) import ([\w, ]+?)\s*(?:#.*)?$|^\s*import (gbviewer[\w.]*)", re.M)


def is_module(name: str) -> bool:
    try:
        importlib.import_module(name)
    except ImportError:
        return False
    return True


def unresolved_imports(text: str) -> list[str]:
    """The gbviewer imports of `text`'s Python examples that do not resolve: 'module: no name' or 'module: why'."""
    out = []
    for block in PYTHON_BLOCK.findall(text):
        for m in IMPORT.finditer(block):
            module = m.group(1) or m.group(3)
            try:
                found = importlib.import_module(module)
            except ImportError as exc:
                out.append(f"{module}: {exc}")
                continue
            for name in (m.group(2) or "").replace(" ", "").split(","):
                if name and not hasattr(found, name) and not is_module(f"{module}.{name}"):
                    out.append(f"{module}: no {name}")
    return out


def test_unresolved_imports_are_found():
    sample = (
        "```python\nfrom gbviewer import camera_paths, render  # x\nfrom gbviewer.outputs import video\n"
        "import gbviewer.nowhere\n```\nfrom gbviewer import x\n"
    )
    assert unresolved_imports(sample) == [
        "gbviewer: no camera_paths",
        "gbviewer.nowhere: No module named 'gbviewer.nowhere'",
    ]


@pytest.mark.parametrize(
    "doc", [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))], ids=lambda p: str(p.relative_to(REPO))
)
def test_python_examples_import(doc: Path):
    missing = unresolved_imports(doc.read_text())
    assert not missing, f"{doc.relative_to(REPO)}: " + "; ".join(missing)
