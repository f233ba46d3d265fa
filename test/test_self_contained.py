"""The repository stands alone: no file points outside it, and the documents' links resolve.

A fresh clone with no sibling folders must pass every test, so nothing may read data from, or send a
reader to, a path outside the repository. Interface sections are cited as ``docs/interfaces.md §N``.
The forbidden patterns are assembled from pieces so that this file does not match itself.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SKIP_DIRS = {".git", ".venv", "out", "build", "install", "log", "__pycache__", ".ruff_cache", ".mypy_cache",
             ".pytest_cache"}
SHARED = "sha" + "red"
CONTRACTS = "contr" + "acts"

# (pattern, what it means); case-insensitive
FORBIDDEN = [
    (re.escape("../" + SHARED), "a sibling folder of the repository"),
    (re.escape("/" + "work/"), "an absolute path of one machine"),
    (re.escape(SHARED + "/data"), "data outside the repository (copy it to test/data/)"),
    (re.escape(SHARED + "/" + CONTRACTS), "a document outside the repository"),
    (re.escape(CONTRACTS + ".md"), "a document outside the repository"),
    (CONTRACTS + r"\s*(§|section)", "an old citation: cite docs/interfaces.md §N"),
    (r"(?<![\w.])/(home|Users|root)/\w", "an absolute home path"),
    (r"[A-Za-z]:\\Users\\", "an absolute home path"),
]
FORBIDDEN_RE = [(re.compile(p, re.IGNORECASE), why) for p, why in FORBIDDEN]


def repository_files() -> list[Path]:
    """Tracked and untracked-but-not-ignored files (git), or a walk of the tree without git."""
    git = shutil.which("git")
    if git and (ROOT / ".git").exists():
        res = subprocess.run([git, "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                             capture_output=True, check=False)
        if res.returncode == 0:
            names = [n for n in res.stdout.decode().split("\0") if n]
            return sorted(ROOT / n for n in names if (ROOT / n).is_file())
    out = []
    for p in ROOT.rglob("*"):
        rel = p.relative_to(ROOT).parts
        if p.is_file() and not any(part in SKIP_DIRS or part.endswith(".egg-info") for part in rel):
            out.append(p)
    return sorted(out)


def text_of(path: Path) -> str | None:
    """The file as text, or None for binary files (NUL bytes or not UTF-8)."""
    data = path.read_bytes()
    if b"\0" in data[:8192]:
        return None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


FILES = repository_files()
TEXTS = {p: t for p in FILES if (t := text_of(p)) is not None}


def test_the_walk_sees_the_repository():
    rel = {p.relative_to(ROOT).as_posix() for p in TEXTS}
    assert {"README.md", "docs/interfaces.md", "test/conftest.py", "shm_ros/__init__.py"} <= rel


def test_no_reference_outside_the_repository():
    hits = []
    for path, text in TEXTS.items():
        for n, line in enumerate(text.splitlines(), start=1):
            for rx, why in FORBIDDEN_RE:
                if rx.search(line):
                    hits.append(f"{path.relative_to(ROOT)}:{n}: {why}: {line.strip()[:120]}")
    assert not hits, "\n".join(hits)


_PARENTS = re.compile(r"\.parents\[(\d+)\]")
_PARENT_CHAIN = re.compile(r"__file__\)?((?:\.resolve\(\))?(?:\.parent)+)\b(?!s)")


def test_no_python_file_climbs_out_of_the_repository():
    """``Path(__file__).parents[N]`` (or a chain of ``.parent``) must stay inside the repository."""
    hits = []
    for path, text in TEXTS.items():
        if path.suffix != ".py":
            continue
        depth = len(path.relative_to(ROOT).parts) - 1  # folders between the root and the file
        for n, line in enumerate(text.splitlines(), start=1):
            if "__file__" not in line:
                continue
            levels = [int(m.group(1)) for m in _PARENTS.finditer(line)]
            levels += [m.group(1).count(".parent") - 1 for m in _PARENT_CHAIN.finditer(line)]
            if any(k > depth for k in levels):
                hits.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()}")
    assert not hits, "\n".join(hits)


def test_the_climb_check_catches_an_escape():
    depth = 1  # a file in test/
    here = "Path(" + "__fi" + "le__).resolve()"

    def level(line: str) -> int:
        m = _PARENTS.search(line)
        if m:
            return int(m.group(1))
        c = _PARENT_CHAIN.search(line)
        assert c, line
        return c.group(1).count(".parent") - 1

    assert level(here + ".parents[2] / 'x'") > depth
    assert level(here + ".parents[1] / 'x'") <= depth
    assert level(here + ".parent.parent.parent / 'x'") > depth
    assert level(here + ".parent.parent / 'x'") <= depth
    assert any(rx.search("see ../" + SHARED + "/data/x") for rx, _ in FORBIDDEN_RE)
    assert any(rx.search(CONTRACTS.capitalize() + " section 2") for rx, _ in FORBIDDEN_RE)
    assert not any(rx.search("docs/interfaces.md §2, a shared 2-core machine") for rx, _ in FORBIDDEN_RE)


# -- markdown links ---------------------------------------------------------------------------

_FENCE = re.compile(r"^(```|~~~).*?^\1[ \t]*$", re.MULTILINE | re.DOTALL)
_CODE_SPAN = re.compile(r"`[^`\n]*`")
_LINK = re.compile(r"!?\[[^\]\n]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*#*\s*$", re.MULTILINE)


def _prose(text: str) -> str:
    return _CODE_SPAN.sub("", _FENCE.sub("", text))


def anchors(text: str) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens, repeats numbered."""
    out: set[str] = set()
    for title in _HEADING.findall(_FENCE.sub("", text)):
        title = re.sub(r"`([^`]*)`", r"\1", title)
        title = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", title)
        slug = re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-")
        k, cand = 0, slug
        while cand in out:
            k += 1
            cand = f"{slug}-{k}"
        out.add(cand)
    return out


MARKDOWN = sorted(p for p in TEXTS if p.suffix == ".md")


def test_markdown_files_are_checked():
    rel = {p.relative_to(ROOT).as_posix() for p in MARKDOWN}
    assert "README.md" in rel and "docs/interfaces.md" in rel


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_relative_links_resolve_inside_the_repository(path: Path):
    text = TEXTS[path]
    bad = []
    for target in _LINK.findall(_prose(text)):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.IGNORECASE):  # http:, https:, mailto:
            continue
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        try:
            dest.relative_to(ROOT)
        except ValueError:
            bad.append(f"{target}: outside the repository")
            continue
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest.read_text(encoding="utf-8")):
            bad.append(f"{target}: no heading with anchor #{anchor} in {dest.relative_to(ROOT)}")
    assert not bad, f"{path.relative_to(ROOT)}:\n" + "\n".join(bad)


def test_interfaces_document_keeps_its_numbering():
    """Code cites ``docs/interfaces.md §N``: sections 1..8 exist in order."""
    text = (ROOT / "docs" / "interfaces.md").read_text(encoding="utf-8")
    numbers = [int(m) for m in re.findall(r"^## (\d+)\. ", text, re.MULTILINE)]
    assert numbers == [1, 2, 3, 4, 5, 6, 7, 8]


def test_every_cited_section_exists():
    cited = set()
    for text in TEXTS.values():
        cited |= {int(n) for n in re.findall(r"interfaces\.md §(\d+)", text)}
    assert cited and cited <= set(range(1, 9)), sorted(cited)
