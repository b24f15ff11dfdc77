"""Opening a report never runs what a config, a CSV or a file name put in it.

Hostile strings (a script, an image with an error handler, a quote that would open an
attribute, an SVG with a load handler, a javascript: URL) go into every text field that
reaches a page: the experiment's title, the resolved config, controller labels, signals,
units, statuses and notes of metrics.csv, figure file names, a sweep's varied values and
parameter names, the claims and table files of a reproduction. Each page must show them as
text: in Chromium (headless, Debian's `chromium`, as in test_report_browser.py) nothing runs
whatever is hovered or opened; the Markdown twin, rendered by a renderer that passes inline
HTML, holds no tag or link of theirs.
"""

from __future__ import annotations

import csv
import json
import re
import shutil
from collections.abc import Iterator
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import jinja2
import pandas as pd
import pytest
import yaml
from markdown_it import MarkdownIt
from playwright.sync_api import Browser, Page, sync_playwright
from test_report_browser import ARGS, chromium
from typer.testing import CliRunner

from nlcx import manifest
from nlcx.cli import app
from nlcx.pages import kinds, markup, render

ROOT = Path(__file__).resolve().parents[1]
CONFIGS = ROOT / "configs"
PWN = "document.body.setAttribute('data-pwned','1')"
HOSTILE = (
    f"<script>{PWN}</script>",
    f'<img src=x onerror="{PWN}">',
    f'" onmouseover="{PWN}" x="',
    f"'><svg onload={PWN}>",
    f"javascript:{PWN}",
)
#: The experiment's title: every hostile string at once.
TITLE = " · ".join(HOSTILE)
runner = CliRunner()


def file_name(text: str, suffix: str) -> str:
    """A hostile string as a file name: ``/`` is the one character a name cannot hold."""
    return text.replace("/", "∕") + suffix


def write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    with path.open("w", newline="", encoding="utf-8") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]), quoting=csv.QUOTE_NONNUMERIC)
        writer.writeheader()
        writer.writerows(rows)


def report(directory: Path) -> None:
    """``nlcx report`` of a directory whose files were written or edited here: marked, and its
    manifest's checksums recorded anew, as if nlcx had written the hostile values itself."""
    record = json.loads((directory / "manifest.json").read_text()) if (directory / "manifest.json").is_file() else {}
    record[manifest.MARKER] = render.kind_of(directory)
    manifest.write(directory, record)
    result = runner.invoke(app, ["report", str(directory), "--configs", str(CONFIGS / "thesis")])
    assert result.exit_code == 0, result.output


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real run with a hostile title, then its metrics.csv given hostile labels, signals,
    units, statuses and notes, its manifest hostile labels, and figures with hostile names."""
    tmp = tmp_path_factory.mktemp("hostile_run")
    raw = yaml.safe_load((CONFIGS / "x_error_ags.yaml").read_text())
    config = tmp / "hostile.yaml"
    config.write_text(yaml.safe_dump({**raw, "title": TITLE}, allow_unicode=True))
    out = tmp / "run"
    result = runner.invoke(app, ["run", str(config), "simulation.t_end=2", "--out", str(out), "--no-report"])
    assert result.exit_code == 0, result.output
    with (out / "metrics.csv").open(newline="", encoding="utf-8") as file:
        rows = list(csv.DictReader(file))
    hostile_rows = []
    for k, label in enumerate(HOSTILE):  # five controllers, the second one not ok
        source = [r for r in rows if r["controller"] == ("conventional", "proposed")[k % 2]]
        for j, row in enumerate(source):
            theta = row["signal"] == "theta"
            hostile_rows.append({
                **row,
                "controller": label,
                "signal": HOSTILE[3] if theta else row["signal"],
                "unit": HOSTILE[4] if theta else row["unit"],
                "status": HOSTILE[0] if k == 1 else "ok",
                "note": HOSTILE[(j + k) % len(HOSTILE)],
            })  # fmt: skip
        hostile_rows.append({**source[0], "controller": label, "metric": HOSTILE[1], "note": HOSTILE[2]})
    write_csv(out / "metrics.csv", hostile_rows)
    manifest = json.loads((out / "manifest.json").read_text())
    manifest["runs"] = [{**manifest["runs"][0], "controller": label, "reason": label} for label in HOSTILE]
    (out / "manifest.json").write_text(json.dumps(manifest))
    for text in HOSTILE:
        shutil.copyfile(out / "figure.png", out / file_name(text, ".png"))
    report(out)
    return out


@pytest.fixture(scope="module")
def sweep_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A sweep directory as `nlcx sweep` writes it, over a text key whose values are hostile,
    with a hostile title, controller labels and parameter name."""
    out = tmp_path_factory.mktemp("hostile_sweep")
    (out / "config.yaml").write_text(yaml.safe_dump({"name": "hostile", "title": TITLE}, allow_unicode=True))
    n = 2 * len(HOSTILE)
    write_csv(out / "sweep.csv", [
        {"variant": i, "value:uncertainty.friction.model": HOSTILE[i % len(HOSTILE)],
         "value:plant.params.M": 0.9 + 0.02 * i, f"value:{HOSTILE[2]}": float(i), "status": "ok"}
        for i in range(n)
    ])  # fmt: skip
    write_csv(out / "metrics.csv", [
        {"variant": i, "controller": label, "signal": "x", "metric": metric, "value": value + 0.1 * i + k,
         "unit": unit, "status": "ok", "note": HOSTILE[k]}
        for i in range(n)
        for k, label in enumerate(HOSTILE[:2])
        for metric, value, unit in (("rise_time", 1.0, "s"), ("ise", 0.5, HOSTILE[3]))
    ])  # fmt: skip
    report(out)
    return out


#: Claims of a reproduction: (source, claim, verdict, evidence), every field hostile somewhere.
CLAIMS = [(HOSTILE[i], HOSTILE[(i + 1) % 5], ("yes", "partly", "no", HOSTILE[3], "yes")[i], HOSTILE[(i + 2) % 5])
          for i in range(len(HOSTILE))]  # fmt: skip


@pytest.fixture(scope="module")
def reproduction_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A reproduction directory (claims.csv, tables/, manifest.json) with hostile claims, cell
    labels (drawn in the SVG charts), a hostile table file name and a hostile command."""
    out = tmp_path_factory.mktemp("hostile_reproduction")
    write_csv(out / "claims.csv", [
        {"chapter": 2, "pendulum": "x", "id": f"c{i}", "source": s, "claim": c, "reproduced": v, "evidence": e}
        for i, (s, c, v, e) in enumerate(CLAIMS)
    ])  # fmt: skip
    (out / "tables").mkdir()
    table = [
        {"signal": label, "metric": "tr", "controller": controller, "thesis": 2.0 + k, "nlcx": 2.1 + k}
        for label in HOSTILE
        for k, controller in enumerate(("conventional", "proposed"))
    ]
    write_csv(out / "tables" / "table_9_1.csv", table)
    write_csv(out / "tables" / file_name(HOSTILE[1], ".csv"), table)
    manifest = {"nlcx_output": "reproduction", "command": f"nlcx reproduce {HOSTILE[4]}", "profile": HOSTILE[1],
                "versions": {"nlcx": HOSTILE[0]}}  # fmt: skip
    (out / "manifest.json").write_text(json.dumps(manifest))
    report(out)
    return out


# -- in Chromium -------------------------------------------------------------------------------

#: Synthetic events on every element: an inline handler that got in would run on them.
FIRE = """() => {
  for (const e of document.querySelectorAll('*')) {
    for (const type of ['mouseover', 'mouseenter', 'mousemove', 'focus', 'load', 'error', 'animationstart']) {
      e.dispatchEvent(new Event(type, {bubbles: true}));
    }
  }
}"""
#: What a page holds that could run: handler attributes, scripts, and links or sources that
#: are not files (a file:// page links only to files beside it).
RUNNABLE = """() => ({
  handlers: [...document.querySelectorAll('*')].flatMap(
    e => [...e.attributes].filter(a => a.name.toLowerCase().startsWith('on')).map(a => e.tagName + ' ' + a.name)),
  scripts: [...document.scripts].map(s => s.textContent),
  urls: [...document.querySelectorAll('[href], [src]')].map(e => e.href || e.src)
        .filter(u => typeof u === 'string' && !u.startsWith('file:')),
  frames: document.querySelectorAll('iframe, object, embed, frame').length,
})"""


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    with sync_playwright() as p:
        launched = p.chromium.launch(executable_path=chromium(), args=ARGS)
        yield launched
        launched.close()


def shipped_scripts(template: str) -> list[str]:
    """The scripts a template itself holds (its <script> elements' text), read from the folder of
    its kind's page (``reproduction.html.j2``: the reproduction page's)."""
    folder = kinds.page(template.split(".")[0]).templates
    return re.findall(r"<script>(.*?)</script>", (folder / template).read_text(), flags=re.S)


def open_and_provoke(browser: Browser, page_file: Path) -> tuple[Page, dict[str, Any], list[str]]:
    """The page loaded, its <details> opened, every element given synthetic events and every
    visible element that holds a hostile text hovered and clicked; what could run on it, and
    the dialogs that opened."""
    page = browser.new_page(viewport={"width": 1280, "height": 900})
    dialogs: list[str] = []
    page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
    page.goto(page_file.as_uri())
    page.wait_for_load_state("load")
    for summary in page.locator("summary").all():
        summary.click(position={"x": 4, "y": 4})  # the toggle, not a link inside the summary
    page.evaluate(FIRE)
    marked = page.evaluate("""() => {
      const seen = new Set();
      for (const e of document.querySelectorAll('body *')) {
        const own = [...e.childNodes].some(c => c.nodeType === 3 && c.textContent.includes('pwned'));
        const attr = ['alt', 'src', 'href', 'title'].some(a => (e.getAttribute(a) || '').includes('pwned'));
        const key = e.tagName + '|' + e.textContent + '|' + (e.getAttribute('src') || '');
        if ((own || attr) && e.getClientRects().length && !e.closest('a') && !seen.has(key)) {
          e.setAttribute('data-probe', '');
          seen.add(key);
        }
      }
      return seen.size;
    }""")
    assert marked > 0
    for element in page.locator("[data-probe]").all():
        element.hover(force=True, timeout=5000)
        element.click(force=True, timeout=5000)
    runnable = page.evaluate(RUNNABLE)
    runnable["pwned"] = page.evaluate("() => document.body.getAttribute('data-pwned')")
    return page, runnable, dialogs


def assert_nothing_ran(runnable: dict[str, Any], dialogs: list[str], template: str) -> None:
    assert runnable["pwned"] is None and dialogs == []
    assert runnable["handlers"] == [] and runnable["urls"] == [] and runnable["frames"] == 0
    assert [s.strip() for s in runnable["scripts"]] == [s.strip() for s in shipped_scripts(template)]


def texts(page: Page, selector: str) -> list[str]:
    return page.eval_on_selector_all(selector, "es => es.map(e => e.textContent)")


@pytest.mark.browser
def test_a_run_page_shows_hostile_fields_as_text_and_runs_nothing(browser: Browser, run_dir: Path) -> None:
    page, runnable, dialogs = open_and_provoke(browser, run_dir / "report.html")
    assert_nothing_ran(runnable, dialogs, "run.html.j2")
    body = page.inner_text("body")
    assert all(text in body for text in HOSTILE)
    assert page.inner_text("header p") == TITLE
    assert page.eval_on_selector("#config pre", "e => e.textContent") == (run_dir / "config.yaml").read_text()
    assert TITLE in yaml.safe_load((run_dir / "config.yaml").read_text())["title"]
    metrics = pd.read_csv(run_dir / "metrics.csv", keep_default_na=False, dtype=str)
    cells = page.eval_on_selector_all(
        "#metrics-table tr", "rs => rs.slice(1).map(r => [...r.cells].map(c => c.textContent))"
    )
    for column in ("controller", "signal", "metric", "unit", "status", "note"):
        k = ["controller", "signal", "metric", "value", "unit", "status", "note"].index(column)
        assert [row[k] for row in cells] == metrics[column].tolist(), column
    header = texts(page, "table.comparison:first-of-type tr:first-child th")
    assert header[2:7] == list(HOSTILE) and header[7:-1] == [f"{c} vs {HOSTILE[0]} (%)" for c in HOSTILE[1:]]
    assert header[-1] == "better"
    assert HOSTILE[3] in texts(page, "#comparison h3")
    assert set(texts(page, "table.comparison td.status")) == {HOSTILE[0]}  # the run that is not ok
    figures = sorted(p.name for p in run_dir.glob("*.png"))
    assert texts(page, "figcaption") == figures
    shown = page.eval_on_selector_all("img.figure", "es => es.map(e => [e.naturalWidth, e.getAttribute('src')])")
    assert all(width > 0 for width, _ in shown)  # the hostile names link to their files
    assert "./javascript%3A" + "document.body.setAttribute%28%27data-pwned%27%2C%271%27%29.png" in [s for _, s in shown]
    page.close()


@pytest.mark.browser
def test_a_sweep_page_shows_hostile_values_as_text_and_runs_nothing(browser: Browser, sweep_dir: Path) -> None:
    page, runnable, dialogs = open_and_provoke(browser, sweep_dir / "report.html")
    assert_nothing_ran(runnable, dialogs, "sweep.html.j2")
    assert all(text in page.inner_text("body") for text in HOSTILE)
    assert page.inner_text("header p").startswith(TITLE + " · ")
    described = texts(page, "#parameters p.muted")
    assert described[0] == f"{len(HOSTILE)} distinct values: " + ", ".join(HOSTILE)
    assert texts(page, "#parameters h3") == ["uncertainty.friction.model", "plant.params.M", HOSTILE[2]]
    assert set(texts(page, "#summary-table td:first-child")) == set(HOSTILE[:2])
    assert HOSTILE[3] in texts(page, "#summary-table td:nth-child(4)")
    page.close()


@pytest.mark.browser
def test_a_reproduction_page_shows_hostile_claims_and_labels_as_text_and_runs_nothing(
    browser: Browser, reproduction_dir: Path
) -> None:
    page, runnable, dialogs = open_and_provoke(browser, reproduction_dir / "report.html")
    assert_nothing_ran(runnable, dialogs, "reproduction.html.j2")
    assert all(text in page.inner_text("body") for text in HOSTILE)
    rows = page.eval_on_selector_all(
        "#claims-table tr[data-verdict]", "rs => rs.map(r => [...r.cells].map(c => c.textContent))"
    )
    assert [(r[1], r[2], r[0], r[3]) for r in rows] == CLAIMS  # source, claim, verdict, evidence
    labels = texts(page, "svg.bars text")
    assert labels == [f"{label} · tr" for label in HOSTILE] * 2  # two tables, one group a signal
    tips = texts(page, "svg.bars title")
    assert tips[0] == f"{HOSTILE[0]} · tr: thesis conventional = 2"
    assert any(file_name(HOSTILE[1], ".csv") in h for h in texts(page, "#tables h3"))
    assert page.inner_text("#summary dd code") == f"nlcx reproduce {HOSTILE[4]}"
    page.close()


# -- the Markdown twins and the environment ----------------------------------------------------


class Tags(HTMLParser):
    """The tags, attributes and text of an HTML fragment."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.text: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))

    def handle_data(self, data: str) -> None:
        self.text.append(data)


def rendered_markdown(path: Path) -> Tags:
    """A Markdown page rendered as a renderer that passes inline HTML and any link would."""
    md = MarkdownIt("commonmark", {"html": True}).enable("table")
    md.validateLink = lambda url: True  # the page itself must keep javascript: out
    parsed = Tags()
    parsed.feed(md.render(path.read_text(encoding="utf-8")))
    return parsed


MARKDOWN_TAGS = {"h1", "h2", "h3", "p", "ul", "li", "table", "thead", "tbody", "tr", "th", "td", "pre", "code", "img",
                 "a", "em", "strong"}  # fmt: skip


@pytest.mark.parametrize("fixture", ["run_dir", "sweep_dir", "reproduction_dir"])
def test_the_markdown_twin_holds_hostile_fields_as_text(fixture: str, request: pytest.FixtureRequest) -> None:
    directory: Path = request.getfixturevalue(fixture)
    parsed = rendered_markdown(directory / "report.md")
    assert {tag for tag, _ in parsed.tags} <= MARKDOWN_TAGS
    assert all(not name.startswith("on") for _, attrs in parsed.tags for name in attrs)
    links = [attrs.get("href") or attrs.get("src") or "" for tag, attrs in parsed.tags if tag in ("a", "img")]
    assert all(link.startswith(("./", "../")) for link in links), links  # relative: no scheme
    text = "".join(parsed.text)
    assert all(hostile in text for hostile in HOSTILE)


def test_the_environment_escapes_html_and_markdown_templates_by_default() -> None:
    templates = {"t.html.j2": "<p>{{ v }}</p><a href='{{ v }}'>", "t.md.j2": "| {{ v }} |", "t.txt": "{{ v }}"}
    env = render.environment().overlay(loader=jinja2.DictLoader(templates))
    value = f"[x](javascript:{PWN}) | <b>&amp;</b> `a` \\"
    html = env.get_template("t.html.j2").render(v=value)
    assert "<b>" not in html and html.count("&lt;b&gt;") == 2 and "&amp;amp;" in html and "&#39;" in html
    assert env.get_template("t.txt").render(v="<b>") == "&lt;b&gt;"  # anything but Markdown: HTML
    md = env.get_template("t.md.j2").render(v=value)
    assert md == r"| \[x\](javascript:" + PWN + r") \| &lt;b&gt;&amp;amp;&lt;/b&gt; \`a\` \\ |"
    assert env.from_string("{{ v }}").render(v="<b>") == "&lt;b&gt;"
    fenced = env.overlay(loader=jinja2.DictLoader({"f.md.j2": "{{ v | fenced('yaml') }}"})).get_template("f.md.j2")
    assert fenced.render(v="a: ```\n<b>\n") == "````yaml\na: ```\n<b>\n````"


def test_file_links_are_relative_and_quoted_and_code_spans_cannot_be_closed_by_their_text() -> None:
    assert markup.href("javascript:alert(1).png") == "./javascript%3Aalert%281%29.png"
    assert markup.href("report_files/x y.png") == "./report_files/x%20y.png"
    assert markup.href("../docs/errata.md") == "../docs/errata.md"
    assert markup.code("nlcx run a|b `c`") == "`` nlcx run a\\|b `c` ``"
    assert markup.fenced("x\n```\n") == "````\nx\n```\n````"
