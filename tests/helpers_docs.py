"""The user's guide as tests read it: README.md and the topic pages under docs/."""

from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
DOCS = REPO / "docs"


def page(name: str) -> str:
    """The text of README.md (name "README") or of docs/<name>.md."""
    return (README if name == "README" else DOCS / f"{name}.md").read_text()


def guide_text() -> str:
    """README.md, then every docs/*.md page, one after the other: for facts that a test holds
    the guide to wherever a page states them."""
    return "\n\n".join([README.read_text()] + [p.read_text() for p in sorted(DOCS.glob("*.md"))])
