"""The docs a user gets: they point only at what the repository ships, and the README reads in short paragraphs.

Users have the repository, not the project's design folder or its issue tracker:
a reference to either is a dead end for them.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FORBIDDEN = re.compile(
    r"SCENE_FORMAT\.md|SMOKE_MODEL\.md|CONTROL_API\.md|ARCHITECTURE\.md|CLI\.md|TRANSPORTS\.md"
    r"|SCIP_URG04LX\.md|LMS2XX_LMS200\.md|\.\./shared|\b[Ii]ssues? #?\d+\b"
)
TEXT_SUFFIXES = {".py", ".md", ".toml", ".yaml", ".yml", ".cfg", ".txt", ""}
MARKDOWN_LINK = re.compile(r"\]\(([^)\s]+)\)")
MAX_README_PARAGRAPH_WORDS = 150


def _tracked_text_files() -> list[Path]:
    names = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    files = [ROOT / name for name in names]
    return [f for f in files if f.suffix in TEXT_SUFFIXES and f.is_file() and f.name != Path(__file__).name and "data" not in f.parts]


def test_nothing_points_at_files_the_repository_does_not_ship_or_at_issue_numbers() -> None:
    offenders = []
    for path in _tracked_text_files():
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            if FORBIDDEN.search(line):
                offenders.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:100]}")
    assert not offenders, "\n".join(offenders)


@pytest.mark.parametrize("doc", [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "scenes" / "README.md"], ids=lambda p: p.name)
def test_relative_links_resolve(doc: Path) -> None:
    missing = []
    for target in MARKDOWN_LINK.findall(doc.read_text(encoding="utf-8")):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        path = (doc.parent / target.split("#", 1)[0]).resolve()
        if not path.exists():
            missing.append(target)
    assert not missing, f"{doc.name} links to files that do not exist: {missing}"


def test_readme_paragraphs_are_short() -> None:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    long = []
    for paragraph in re.split(r"\n\s*\n", text):
        if paragraph.lstrip().startswith(("|", "#", "<", "!")):
            continue  # tables, headings, HTML, pictures
        words = len(paragraph.split())
        if words > MAX_README_PARAGRAPH_WORDS:
            long.append(f"{words} words: {paragraph.strip()[:80]}…")
    assert not long, "\n".join(long)
