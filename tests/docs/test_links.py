"""Every relative link and image in README.md, docs/*.md and hardware/*.md points at a file or
folder of the repository, and every `#anchor` at a heading of its page (GitHub's anchors)."""

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")),
         *sorted((REPO / "hardware").glob("*.md"))]
# [text](target) and ![alt](target); the target may carry a "title".
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")


def _prose(text: str) -> str:
    """The page without its code: fenced blocks and inline code hold no links."""
    text = re.sub(r"^(```|~~~).*?^\1", "", text, flags=re.S | re.M)
    return re.sub(r"`[^`\n]*`", "", text)


def anchors(text: str) -> set[str]:
    """GitHub's anchors of a page's headings: the heading's text lowercased, its punctuation
    (but hyphens and underscores) dropped, spaces to hyphens; a repeat gets -1, -2, ..."""
    seen, out = {}, set()
    for line in re.sub(r"^(```|~~~).*?^\1", "", text, flags=re.S | re.M).splitlines():
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        title = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", m.group(1))  # a link: its text
        title = re.sub(r"<[^>]+>", "", title)
        slug = re.sub(r"[^\w\- ]", "", title.lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def _links(page: Path):
    for target in LINK.findall(_prose(page.read_text())):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):  # http:, https:, mailto:
            continue
        yield target


def test_the_pages_exist():
    assert (REPO / "README.md") in PAGES
    assert len([p for p in PAGES if p.parent.name == "docs"]) >= 10


def test_the_anchor_rules():
    text = "# The hard promise: safety filter, kinetostatic limit\n## `cdpm run`\n## Run\n## Run\n"
    assert anchors(text) == {"the-hard-promise-safety-filter-kinetostatic-limit", "cdpm-run",
                             "run", "run-1"}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_resolves(page):
    broken = []
    for target in _links(page):
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            broken.append(target)
        elif anchor and file.suffix == ".md" and anchor not in anchors(file.read_text()):
            broken.append(target)
    assert not broken, f"{page.relative_to(REPO)}: {broken}"
