"""SVG text (placeholder)."""

from __future__ import annotations


def text_items(doc, el, name, c, style):
    doc.skipped["text" if name == "text" else name] += 1
    return []
