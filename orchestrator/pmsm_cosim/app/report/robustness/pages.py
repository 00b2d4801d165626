"""A generated section of a documentation page: the lines between two markers replaced, the rest of the
page left as it is (appended where the page has no such section yet)."""

from __future__ import annotations

from pathlib import Path


def write_between(page: Path, lines: list[str], begin: str, end: str) -> None:
    """Write ``lines`` (the first ``begin``, the last ``end``) into ``page`` in place of its section."""
    text = page.read_text(encoding="utf-8") if page.exists() else ""
    block = "\n".join(lines)
    if begin in text and end in text:
        head, rest = text.split(begin, 1)
        text = head + block + rest.split(end, 1)[1]
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    page.write_text(text, encoding="utf-8")
