"""Reports as Markdown and as one self-contained HTML page, rendered by markdown-it-py.

The reports a person reads (the alignment report, the leaderboard) are written once, as Markdown;
the HTML page is that same Markdown rendered by `markdown-it-py <https://markdown-it-py.readthedocs.io>`_
(CommonMark plus GitHub tables; raw HTML in the text is escaped, never passed through). A few
changes are made on the parsed tokens, not on text:

* a paragraph that holds only an image becomes ``<figure>`` with the image's alt text as its
  ``<figcaption>``;
* images whose link is a key of ``images`` are inlined as ``data:`` URIs, so the page needs no
  other file; links that are keys of ``links`` are replaced (e.g. ``report.md`` -> ``report.html``);
* ``cls`` sets the CSS class of the block's top-level elements, ``row_classes`` those of a
  table's body rows (in order).

Pure: strings in, a string out; writing the files is the caller's job.
"""
from __future__ import annotations

import base64
import html
from collections.abc import Mapping, Sequence

from markdown_it import MarkdownIt
from markdown_it.token import Token

_MD = MarkdownIt("commonmark", {"html": False}).enable("table")
_IMAGE_TYPES = {"png": "image/png", "jpg": "image/jpeg", "jpeg": "image/jpeg", "svg": "image/svg+xml"}


def markdown_to_html(text: str, *, cls: str | None = None, row_classes: Sequence[str] | None = None,
                     images: Mapping[str, bytes] | None = None, links: Mapping[str, str] | None = None) -> str:
    """Render a Markdown fragment as an HTML fragment (see the module docstring).

    Args:
        text: Markdown (CommonMark with GitHub-style tables).
        cls: CSS class given to every top-level element of the fragment (None: no class).
        row_classes: CSS class of each table body row, in order ("" for none; None: no classes).
        images: file bytes by the link used in ``text`` (e.g. ``"figures/a.png"``) to inline them.
        links: new targets by the link used in ``text`` (e.g. ``{"view0/report.md": "view0/report.html"}``).
    """
    tokens = _MD.parse(text)
    _set_classes(tokens, cls, row_classes)
    if images:
        _inline_images(tokens, images)
    if links:
        _relink(tokens, links)
    return _MD.renderer.render(_figures(tokens), _MD.options, {})


def html_page(body: str, *, title: str, css: str) -> str:
    """A complete HTML5 page around ``body`` (an HTML fragment) with ``css`` in a style element."""
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title>\n<style>{css}</style></head>\n<body>\n{body}</body></html>\n")


def _set_classes(tokens: list[Token], cls: str | None, row_classes: Sequence[str] | None) -> None:
    rows = iter(row_classes or ())
    in_body = False
    for t in tokens:
        if cls and t.level == 0 and t.nesting == 1:
            t.attrJoin("class", cls)
        if t.type in ("tbody_open", "tbody_close"):
            in_body = t.type == "tbody_open"
        elif in_body and t.type == "tr_open" and row_classes is not None:
            c = next(rows, "")
            if c:
                t.attrSet("class", c)


def _inline_images(tokens: list[Token], images: Mapping[str, bytes]) -> None:
    for t in tokens:
        for child in t.children or ():
            src = child.attrGet("src") if child.type == "image" else None
            if src in images:
                mime = _IMAGE_TYPES.get(str(src).rsplit(".", 1)[-1].lower(), "application/octet-stream")
                child.attrSet("src", f"data:{mime};base64,{base64.b64encode(images[src]).decode()}")


def _relink(tokens: list[Token], links: Mapping[str, str]) -> None:
    for t in tokens:
        for child in t.children or ():
            if child.type == "link_open" and child.attrGet("href") in links:
                child.attrSet("href", links[child.attrGet("href")])


def _figures(tokens: list[Token]) -> list[Token]:
    """Turn every paragraph whose only content is one image into a figure with a caption."""
    out: list[Token] = []
    k = 0
    while k < len(tokens):
        t = tokens[k]
        children = tokens[k + 1].children if t.type == "paragraph_open" and k + 1 < len(tokens) else None
        if children and len(children) == 1 and children[0].type == "image":
            image = children[0]
            caption = _MD.renderer.renderInline(image.children or [], _MD.options, {})
            opening = Token("figure_open", "figure", 1, block=True)
            closing = Token("figure_close", "figure", -1, block=True)
            opening.attrs = dict(t.attrs)
            out += [opening, tokens[k + 1],
                    Token("html_block", "", 0, content=f"<figcaption>{caption}</figcaption>"), closing]
            k += 3
            continue
        out.append(t)
        k += 1
    return out
