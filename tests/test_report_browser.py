"""The reproduction report in a real browser: headless Chromium (Debian's `chromium`) driven by
Playwright for Python; no browser is downloaded. `.ci/run` installs chromium if missing."""

from __future__ import annotations

import shutil
from pathlib import Path
from urllib.parse import unquote, urlparse

import numpy as np
import pandas as pd
import pytest
from matplotlib.image import imread
from playwright.sync_api import sync_playwright

#: Chromium as root needs --no-sandbox; the others keep it off this machine's closed network.
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run"]  # fmt: skip
pytestmark = [pytest.mark.browser, pytest.mark.slow]  # slow too: it needs a whole reproduction


def chromium() -> str:
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    assert path, "Debian's chromium is not installed (apt-get install chromium; .ci/run does it)"
    return path


def test_the_reproduction_page_loads_clean_and_complete_in_chromium(reproduction: Path, tmp_path: Path) -> None:
    page_file = reproduction / "report.html"
    errors: list[str] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium(), args=ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(page_file.as_uri())
        page.wait_for_load_state("load")
        images = page.evaluate("Array.from(document.images).map(i => [i.getAttribute('src'), i.naturalWidth])")
        links = page.evaluate("Array.from(document.querySelectorAll('a[href]')).map(a => a.href)")
        anchors = set(page.evaluate("Array.from(document.querySelectorAll('[id]')).map(e => e.id)"))
        shown = {v: int(page.locator(f'[data-claims="{v}"]').inner_text().split()[-1]) for v in ("yes", "partly", "no")}
        page.locator('.filters button[data-filter="no"]').click()
        visible = page.evaluate("Array.from(document.querySelectorAll('#claims-table tr[data-verdict]'))"
                                ".filter(r => r.offsetParent !== null).map(r => r.dataset.verdict)")  # fmt: skip
        shot = tmp_path / "page.png"
        page.screenshot(path=str(shot), full_page=True)
        browser.close()
    assert errors == []
    assert len(images) >= 95 and all(width > 0 for _, width in images), [s for s, w in images if w == 0][:5]
    local = [urlparse(url) for url in links if urlparse(url).scheme == "file"]
    assert len(local) >= 10, "the page links its runs, figures and tables"
    for parsed in local:
        assert Path(unquote(parsed.path)).exists(), parsed.geturl()
    in_page = [p.fragment for p in local if p.fragment and Path(unquote(p.path)) == page_file]
    assert in_page and set(in_page) <= anchors
    claims = pd.read_csv(reproduction / "claims.csv").reproduced.value_counts()
    assert shown == {v: int(claims.get(v, 0)) for v in ("yes", "partly", "no")}
    assert set(visible) == {"no"} and len(visible) == claims.get("no", 0)
    pixels = imread(shot)
    assert pixels.shape[0] > 2000 and float(np.std(pixels[..., :3])) > 0.05  # a long page, not blank
