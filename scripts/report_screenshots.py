"""Screenshots of a reproduction report for the README (docs/img/), in headless Chromium.

    python scripts/report_screenshots.py results/thesis/report.html docs/img

(`make screenshots`, after `make reproduce`.) Takes the summary, one table section
(Table 2.3) and the start of the figure gallery.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

from playwright.sync_api import sync_playwright

ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run"]  # fmt: skip
SHOTS = {"report_summary.png": "#summary", "report_table.png": "#table_2_3", "report_gallery.png": "#gallery"}


def main(page_file: Path, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    executable = shutil.which("chromium") or "chromium"
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.goto(page_file.resolve().as_uri())
        page.wait_for_load_state("load")
        for name, selector in SHOTS.items():
            box = page.locator(selector).bounding_box()
            assert box is not None, selector
            clip = {"x": 0, "y": box["y"], "width": 1280, "height": min(box["height"], 900)}
            page.screenshot(path=str(out / name), clip=clip, full_page=True)
        browser.close()


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
