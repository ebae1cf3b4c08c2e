"""The SSP side of archive safety: SspError, and the SSD's `source` URIs resolved strictly
inside the archive. The member checks, limits and extraction every archive shares (an .ssp and
the FMUs in it alike) are in archive.py and re-exported here."""

from __future__ import annotations

import urllib.parse
import xml.etree.ElementTree as ET
from collections.abc import Collection

from impedance_cosim.cosim.archive import (
    DEFAULT_LIMITS,
    ArchiveError,
    Limits,
    check_archive,
    check_members,
    checked,
    declared_members,
    extract,
    name_problem,
    open_zip,
    read_member,
    unpack,
)

__all__ = ["DEFAULT_LIMITS", "ArchiveError", "Limits", "SspError", "check_archive"]
__all__ += ["check_members", "checked", "declared_members", "extract", "open_zip", "read_member"]
__all__ += ["resolve_source", "unpack"]

# The SSP 1.0 namespaces (the reader's and the writer's, cosim/system/paper.py) and our annotation
NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
}
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)
ANNOTATION_TYPE = "org.impedance-cosim.master"


class SspError(ArchiveError):
    """The SSP archive is malformed or inconsistent; the message names the problem."""


def resolve_source(uri: str | None, names: Collection[str], what: str) -> str:
    """The archive member a `source` URI names (SSP 1.0: a relative URI, resolved against the
    SSD at the archive root). Absolute or remote URIs, `..`, and anything else that would leave
    the archive are refused; the standard does not require hosts to support them."""
    if uri is None:
        raise SspError(f"{what} has no source")
    try:
        parts = urllib.parse.urlsplit(uri)
        path = urllib.parse.unquote(parts.path, errors="strict")
    except (ValueError, UnicodeError) as exc:
        raise SspError(f"{what}: source {uri!r} is not a valid URI ({exc})") from None
    if parts.scheme or parts.netloc or uri.startswith("//"):
        raise SspError(
            f"{what}: source {uri!r} is an absolute URI; only relative URIs into the archive"
            " are supported"
        )
    if parts.query or parts.fragment:
        raise SspError(f"{what}: source {uri!r} has a query or fragment (not supported)")
    segments = [s for s in path.split("/") if s != "."]
    name = "/".join(segments)
    problem = name_problem(name) if not path.startswith("/") else "an absolute path"
    if problem:
        raise SspError(f"{what}: source {uri!r} has {problem}; it must name a file in the archive")
    if name not in names:
        raise SspError(f"{what}: {name} is missing from the archive")
    return name
