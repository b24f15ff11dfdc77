"""An output directory's report pages written after its results: the outcome recorded in its
manifest, the results kept whatever the pages do (:func:`write_pages`, which ``nlcx run``,
``nlcx sweep``, ``nlcx report`` and every study's command call)."""

from __future__ import annotations

import os
from pathlib import Path

from nlcx import manifest
from nlcx.errors import NlcxError

#: The files a report writes into an output directory (with the folder :data:`PAGE_FOLDER`):
#: its pages and the tables it derives from the results for them.
PAGES = ("report.html", "report.md", "report_summary.csv", "summary.csv", "profiles.csv")
#: The folder of a sweep report's charts.
PAGE_FOLDER = "report_files/"


def is_page(rel: str) -> bool:
    """Whether the relative path ``rel`` is a file a report writes (:data:`PAGES`, :data:`PAGE_FOLDER`)."""
    return rel in PAGES or rel.startswith(PAGE_FOLDER)


class ReportError(NlcxError):
    """A report page that could not be written, after the results were: names the directory
    that holds them and says that its manifest records the failure."""

    exit_code = 1

    def __init__(self, directory: Path, reason: str) -> None:
        self.directory, self.reason = directory, reason
        super().__init__(
            f"report error: {directory}/report.html not written: {reason}; the results are complete in "
            f"{directory}/ and its manifest.json records the failure; allowed: nlcx report {directory} to try again"
        )

    def __reduce__(self) -> tuple[type, tuple[Path, str]]:
        return (type(self), (self.directory, self.reason))


def write_pages(directory: Path, configs: Path | None = None, verify: bool = False) -> str | None:
    """Write ``directory``'s report pages (:func:`nlcx.pages.render.write_report`) after its
    results and manifest, and record the outcome in the manifest (``report``: ok, or failed
    and why; the pages' checksums). Returns None, or the reason the pages failed: the results
    stay, whatever the pages do. An interruption (Ctrl-C) is not a failure of the pages: it
    goes on up.

    ``verify``: first check every file the manifest lists, but the pages, against its
    checksums (:func:`nlcx.manifest.verify`; a directory written before, ``nlcx report``):
    a truncated or altered file is refused (:class:`nlcx.manifest.IntegrityError`), and no
    page is written."""
    from nlcx.pages.render import write_report

    listed = manifest.load(directory).get("checksums", {})
    if verify:
        manifest.verify(directory, [name for name in listed if not is_page(name)])
    pages = [name for name in listed if is_page(name)]
    try:
        write_report(directory, configs)
    except Exception as exc:
        if os.environ.get("NLCX_DEBUG"):
            raise
        lines = str(exc).splitlines()
        reason = lines[0] if lines else "the page could not be rendered"
        if not isinstance(exc, NlcxError):
            reason = f"an internal error of the report ({reason}; set NLCX_DEBUG=1 for a traceback)"
        manifest.update(directory, pages, report={"status": "failed", "error": reason})
        return reason
    manifest.update(directory, pages, report={"status": "ok"})
    return None
