"""What a reader sees of a server-rendered page: its text and its tables, without markup."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from html.parser import HTMLParser

HIDDEN = {"script", "style", "template"}
VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "wbr"}


def _squeeze(text: str) -> str:
    return re.sub(r"\s+", " ", text).strip()


@dataclass
class Page:
    """A page as read: title, headings, body text and each table's data rows (``td`` texts)."""

    title: str = ""
    headings: list[str] = field(default_factory=list)
    text: str = ""
    tables: dict[str, list[list[str]]] = field(default_factory=dict)


class _Reader(HTMLParser):
    """Collects the visible text; tables are keyed by their ``id`` (or ``table<N>``)."""

    def __init__(self) -> None:
        super().__init__()
        self.page = Page()
        self.open: list[str] = []
        self.words: list[str] = []
        self.title: list[str] = []
        self.heading: list[str] | None = None
        self.table: list[list[str]] | None = None
        self.cell: list[str] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag in VOID:
            return
        self.open.append(tag)
        if tag in ("h1", "h2", "h3"):
            self.heading = []
        elif tag == "table":
            self.table = []
            name = dict(attrs).get("id") or f"table{len(self.page.tables)}"
            self.page.tables[name] = self.table
        elif tag == "tr" and self.table is not None:
            self.table.append([])
        elif tag == "td":
            self.cell = []

    def handle_endtag(self, tag: str) -> None:
        if tag in self.open:
            while self.open.pop() != tag:
                pass
        if tag in ("h1", "h2", "h3") and self.heading is not None:
            self.page.headings.append(_squeeze("".join(self.heading)))
            self.heading = None
        elif tag == "table":
            self.table = None
        elif tag == "td" and self.cell is not None and self.table:
            self.table[-1].append(_squeeze("".join(self.cell)))
            self.cell = None

    def handle_data(self, data: str) -> None:
        if HIDDEN & set(self.open):
            return
        if "head" in self.open:  # only the title of the head shows (in the tab)
            if "title" in self.open:
                self.title.append(data)
            return
        self.words.append(data)
        for part in (self.heading, self.cell):
            if part is not None:
                part.append(data)


def read_page(html: str) -> Page:
    """The title, headings, visible body text and tables' data rows of ``html``."""
    reader = _Reader()
    reader.feed(html)
    reader.close()
    page = reader.page
    for name, rows in page.tables.items():
        page.tables[name] = [row for row in rows if row]  # header rows hold no td
    page.title, page.text = _squeeze("".join(reader.title)), _squeeze(" ".join(reader.words))
    return page
