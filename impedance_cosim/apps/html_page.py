"""The HTML pieces of our self-contained pages (report.html): escaping, tables, PNGs as data:
URIs and the page shell with its content security policy (nothing is fetched)."""

from __future__ import annotations

import base64
import html
import json
import re
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# The browser fetches nothing: images only from data: URIs, the one inline style sheet.
CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"
STYLE = """body{font:15px/1.45 system-ui,sans-serif;max-width:72rem;margin:1.5rem auto;
padding:0 1rem;color:#222}h1{font-size:1.5rem}
h2{font-size:1.2rem;border-bottom:1px solid #ccc;margin-top:2rem}
table{border-collapse:collapse;margin:.5rem 0}td,th{border:1px solid #ccc;padding:.2rem .5rem;
text-align:left;vertical-align:top;overflow-wrap:anywhere}th{background:#f3f3f3}
table{display:block;max-width:100%;overflow-x:auto}code,pre{font-size:13px}
pre{white-space:pre-wrap;word-break:break-all;background:#f6f6f6;padding:.5rem}
.ok{background:#e6f4e6;padding:.6rem;border-left:6px solid #2a2}
.failed{background:#fbe7e7;padding:.6rem;border-left:6px solid #c22;font-weight:600}
.diverged{background:#fdf3dc;padding:.6rem;border-left:6px solid #d90;font-weight:600}
figure{margin:1rem 1rem 1rem 0;display:inline-block;vertical-align:top}
img{max-width:100%;height:auto;border:1px solid #ddd}td.n{white-space:nowrap}"""


# --- HTML pieces ------------------------------------------------------------------------------


def esc(value: Any) -> str:
    return html.escape(str(value), quote=True)


# A cell that is one number (801, 0.0025, -1.5e6, 1.20): class "n", never wrapped mid-number.
NUMBER = re.compile(r"-?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


def cell(value: Any) -> str:
    text = esc(value)
    return f'<td class="n">{text}</td>' if NUMBER.fullmatch(str(value)) else f"<td>{text}</td>"


def table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    head = f"<thead><tr>{head}</tr></thead>" if any(header) else ""
    body = "".join("<tr>" + "".join(cell(c) for c in row) + "</tr>" for row in rows)
    return f"<table>{head}<tbody>{body}</tbody></table>"


def plain(value: Any) -> str:
    """A cell value as text: numbers as they are, nested data as compact JSON."""
    if isinstance(value, (dict, list, tuple)):
        return json.dumps(value, default=str)
    return "" if value is None else str(value)


def fixed(value: Any, digits: int) -> str:
    """A measured time or rate as a reader wants it (run.json keeps every digit)."""
    return f"{value:.{digits}f}" if isinstance(value, int | float) else plain(value)


def png_data_uri(path: Path) -> tuple[str, int, int] | None:
    """(data: URI, width, height) of a PNG file; None when it is missing or not a PNG."""
    try:
        data = Path(path).read_bytes()
    except OSError:
        data = b""
    if not data.startswith(PNG_SIGNATURE) or data[12:16] != b"IHDR" or len(data) < 24:
        return None
    width, height = struct.unpack(">II", data[16:24])
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii"), width, height


def page(title: str, body: str) -> str:
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f'<meta http-equiv="Content-Security-Policy" content="{CSP}">\n'
        f"<title>{esc(title)}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n"
        f"<h1>{esc(title)}</h1>\n{body}\n</body>\n</html>\n"
    )
