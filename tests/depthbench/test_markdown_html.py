"""depthbench.markdown_html: the reports' Markdown rendered by markdown-it-py, with figures, inlined
images and CSS classes, checked by parsing the HTML it gives back."""
from __future__ import annotations

import base64
from html.parser import HTMLParser

from depthbench.markdown_html import html_page, markdown_to_html


class _Tags(HTMLParser):
    """Every start tag with its attributes, in document order, and the text."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict]] = []
        self.text: list[str] = []
        self.feed(text)

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))

    handle_startendtag = handle_starttag

    def handle_data(self, data):
        self.text.append(data)


def test_a_paragraph_with_only_an_image_becomes_a_figure_with_its_inlined_png_and_caption():
    png = b"\x89PNG fake bytes"
    out = markdown_to_html("Intro *text*.\n\n![Error against **depth**](figures/e.png)\n\n![x](other.png) and text\n",
                           images={"figures/e.png": png})
    tags = _Tags(out).tags
    names = [t for t, _ in tags]
    assert names.count("figure") == 1 and names.count("figcaption") == 1 and names.count("img") == 2
    first, second = [a for t, a in tags if t == "img"]
    assert first["src"] == "data:image/png;base64," + base64.b64encode(png).decode()
    assert second["src"] == "other.png"                          # not in ``images``: left as a link
    assert "<figcaption>Error against <strong>depth</strong></figcaption>" in out
    assert "<em>text</em>" in out


def test_links_named_in_links_are_replaced_others_kept():
    out = markdown_to_html("[a](v0/report.md), [b](v1/report.md) and [c](https://example.org)",
                           links={"v0/report.md": "v0/report.html"})
    hrefs = [a["href"] for t, a in _Tags(out).tags if t == "a"]
    assert hrefs == ["v0/report.html", "v1/report.md", "https://example.org"]


def test_raw_html_in_the_text_is_escaped_not_passed_through():
    out = markdown_to_html("a <script>alert(1)</script> & b\n\n| x |\n|---|\n| <b>y</b> |\n")
    assert "<script" not in out and "<b>" not in out
    assert "&lt;script&gt;" in out and "&amp;" in out


def test_classes_go_to_top_level_blocks_and_to_table_body_rows_in_order():
    out = markdown_to_html("| m | a |\n|:--|--:|\n| r1 | 1 |\n| r2 | 2 |\n| r3 | 3 |\n",
                           cls="wide", row_classes=["", "separator", "published"])
    tags = _Tags(out).tags
    assert ("table", {"class": "wide"}) in tags
    rows = [a.get("class") for t, a in tags if t == "tr"]
    assert rows == [None, None, "separator", "published"]      # header row, then the three body rows
    assert markdown_to_html("one\n\ntwo\n", cls="note").count('<p class="note">') == 2


def test_page_is_complete_and_escapes_its_title():
    page = html_page("<p>x</p>", title="a <b> report", css="p{color:red}")
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    assert "<title>a &lt;b&gt; report</title>" in page and "<style>p{color:red}</style>" in page
