"""The report's document model: headings, paragraphs, bullets, tables and images, written as
Markdown (images linked relatively) and as one self-contained HTML page (images embedded as
data URIs); and the numbers of the tables as cell text (``ms``, ``ci``, ``spread``, ``db``)."""

from __future__ import annotations

import base64
import html
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ...fileio import inside
from ..stats import no_mark


@dataclass
class Img:
    path: str  # relative to the report
    alt: str = ""
    width: int = 240


@dataclass
class Cells:
    items: list[Any]  # Img or str, stacked in one table cell


Cell = Any  # str | float | Img | Cells | None


class Doc:
    """Headings, paragraphs, tables and image rows; rendered as Markdown and as HTML."""

    def __init__(self) -> None:
        self.blocks: list[tuple[str, Any]] = []

    def h(self, level: int, text: str) -> None:
        self.blocks.append(("h", (level, text)))

    def p(self, text: str) -> None:
        self.blocks.append(("p", text))

    def bullets(self, items: list[str]) -> None:
        if items:
            self.blocks.append(("ul", items))

    def table(self, headers: list[str], rows: list[list[Cell]]) -> None:
        self.blocks.append(("table", (headers, rows)))

    def image(self, img: Img) -> None:
        self.blocks.append(("img", img))

    def markdown(self) -> str:
        out: list[str] = []
        for kind, value in self.blocks:
            if kind == "h":
                out.append("#" * value[0] + " " + value[1])
            elif kind == "p":
                out.append(value)
            elif kind == "ul":
                out.append("\n".join(f"- {i}" for i in value))
            elif kind == "img":
                out.append(f"![{value.alt}]({value.path})")
            else:
                headers, rows = value
                lines = ["| " + " | ".join(headers) + " |",
                         "|" + "|".join(" --- " for _ in headers) + "|"]
                lines += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in rows]
                out.append("\n".join(lines))
        return "\n\n".join(out) + "\n"

    def html(self, title: str, base: Path) -> str:
        """One self-contained page: every image (paths relative to ``base``) is embedded."""
        base = Path(base)
        out = [f"<!doctype html><html><head><meta charset='utf-8'><title>{_e(title)}</title>"
               f"<style>{CSS}</style></head><body>"]
        for kind, value in self.blocks:
            if kind == "h":
                out.append(f"<h{value[0]}>{_e(value[1])}</h{value[0]}>")
            elif kind == "p":
                out.append(f"<p>{_inline(value)}</p>")
            elif kind == "ul":
                out.append("<ul>" + "".join(f"<li>{_inline(i)}</li>" for i in value) + "</ul>")
            elif kind == "img":
                out.append(f"<p>{_html_img(value, base, full=True)}</p>")
            else:
                headers, rows = value
                # a wide table scrolls inside its box instead of widening the page
                out.append("<div class='wide'><table><tr>"
                           + "".join(f"<th>{_e(h)}</th>" for h in headers)
                           + "</tr>" + "".join("<tr>" + "".join(
                               f"<td>{_html_cell(c, base)}</td>" for c in r) + "</tr>" for r in rows)
                           + "</table></div>")
        out.append("</body></html>")
        return "\n".join(out) + "\n"


CSS = ("body{font-family:system-ui,sans-serif;margin:2em;max-width:1400px}"
       ".wide{max-width:100%;overflow-x:auto;margin:0.5em 0 1.5em}"
       "table{border-collapse:collapse}img{max-width:100%;height:auto}"
       "td,th{border:1px solid #ccc;padding:3px 8px;text-align:right;vertical-align:top}"
       "th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}"
       "img{image-rendering:pixelated}code{background:#f3f3f3;padding:0 3px}")


def _e(text: str) -> str:
    return html.escape(str(text))


def _inline(text: str) -> str:
    # the markdown we write inline: `code` and **bold**
    parts = str(text).split("`")
    return "".join(_bold(_e(p)) if i % 2 == 0 else f"<code>{_e(p)}</code>"
                   for i, p in enumerate(parts))


def _bold(text: str) -> str:
    parts = text.split("**")
    return "".join(p if i % 2 == 0 else f"<b>{p}</b>" for i, p in enumerate(parts))


def _md_cell(c: Cell) -> str:
    if isinstance(c, Cells):
        return " ".join(_md_cell(i) for i in c.items)
    if isinstance(c, Img):
        return f"![{c.alt}]({c.path})"
    return "-" if c is None else str(c).replace("|", "\\|").replace("\n", " ")


def data_uri(path: Path) -> str:
    """A PNG file as a ``data:`` URI."""
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode("ascii")


def _html_img(img: Img, base: Path, *, full: bool = False) -> str:
    style = "max-width:100%" if full else f"width:{img.width}px;max-width:100%"
    return (f"<img src='{data_uri(inside(base, img.path))}' alt='{_e(img.alt)}' "
            f"title='{_e(img.path)}' style='{style}'>")


def _html_cell(c: Cell, base: Path) -> str:
    if isinstance(c, Cells):
        return "<br>".join(_html_cell(i, base) for i in c.items)
    if isinstance(c, Img):
        return _html_img(c, base)
    return "-" if c is None else _inline(str(c))


def ms(s: dict[str, Any] | None, key: str = "median") -> str:
    return "-" if not s else f"{s[key]:.3f}"


def ci(s: dict[str, Any] | None) -> str:
    """``lo-hi``; ``lo-hi (n=2<6)`` where too few samples or runs make it no 95% CI."""
    if not s:
        return "-"
    why = no_mark(s)
    return f"{s['ci_lo']:.3f}-{s['ci_hi']:.3f}" + (f" ({why})" if why else "")


def spread(s: dict[str, Any] | None) -> str:
    return "-" if not s else f"{s['p5']:.3f}-{s['p95']:.3f}"


def db(v: float | None) -> str:
    if v is None:
        return "-"
    return "∞ (identical)" if math.isinf(v) else f"{v:.2f} dB"
