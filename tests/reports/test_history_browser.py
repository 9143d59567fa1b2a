"""The published asv dashboard of the committed history, in a real browser (headless Chromium).

``benchmarks/publish.py`` (``asv publish`` with the third-party scripts copied beside the
pages) of ``docs/history/results`` into a temporary folder, served over HTTP as
``asv preview`` serves it (the page fetches its graphs; from ``file://`` it shows an error
page): the summary page draws a graph per benchmark, and its screenshot is taken.
Skipped without asv (the ``history`` extra) or Chromium (``apt-get install chromium``).
"""

import functools
import http.server
import json
import re
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from test_report_browser import chromium  # noqa: F401 - the fixture that finds Chromium

pytestmark = [pytest.mark.browser, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[2]

#: Milliseconds of virtual time Chromium gives the page to fetch its JSON and draw.
VIRTUAL_TIME_BUDGET_MS = 30_000

#: Appended to a copy of the summary page: a while after ``load`` (the graphs are fetched
#: and drawn asynchronously), how many benchmark boxes there are and how many hold a
#: drawing, written into ``data-graphs`` of <body> for ``--dump-dom``.
CHECK_SCRIPT = """
<script>
window.addEventListener("load", () => setTimeout(() => {
  const boxes = Array.from(document.querySelectorAll(".benchmark-container"));
  const drawn = boxes.filter(b => b.querySelector("canvas, svg, img"));
  document.body.setAttribute("data-graphs", JSON.stringify(
      {boxes: boxes.length, drawn: drawn.length}));
}, 10000));
</script>
"""


@pytest.fixture(scope="module")
def published(tmp_path_factory):
    asv = shutil.which("asv")
    if asv is None:
        pytest.skip("asv is not installed (pip install translucent[history])")
    if not any((ROOT / "docs" / "history" / "results").glob("*/*-*.json")):
        pytest.skip("no committed history results")
    html = tmp_path_factory.mktemp("history") / "html"
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "publish.py"),
                           "--html-dir", str(html)], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    # nothing is loaded from outside the folder
    for page in html.glob("*.html"):
        assert not re.search(r'<(script|link)[^>]*(src|href)="https?://', page.read_text())
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(html))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield html, f"http://127.0.0.1:{server.server_address[1]}/"
    server.shutdown()


def test_the_dashboard_draws_a_graph_per_benchmark(chromium, published, tmp_path):  # noqa: F811
    html, url = published
    page = (html / "index.html").read_text()
    (html / "graph_check.html").write_text(page.replace("</body>", CHECK_SCRIPT + "</body>"))
    common = [chromium, "--headless", "--no-sandbox", "--disable-gpu",
              f"--virtual-time-budget={VIRTUAL_TIME_BUDGET_MS}"]
    # the grid draws a graph when it scrolls into view: a window tall enough for all
    result = subprocess.run(common + ["--window-size=1400,4000", "--dump-dom",
                                      url + "graph_check.html"],
                            capture_output=True, text=True, timeout=180)
    assert result.returncode == 0, result.stderr[-2000:]
    match = re.search(r'data-graphs="([^"]*)"', result.stdout)
    assert match, "the page never ran its check: " + result.stdout[:500]
    graphs = json.loads(match.group(1).replace("&quot;", '"'))
    benchmarks = json.loads((html / "index.json").read_text())["benchmarks"]
    assert graphs["boxes"] >= len(benchmarks) > 0
    assert graphs["drawn"] == graphs["boxes"], graphs
    screenshot = tmp_path / "dashboard.png"
    shot = subprocess.run(common + ["--window-size=1400,900", f"--screenshot={screenshot}",
                                    url + "index.html"],
                          capture_output=True, text=True, timeout=180)
    assert shot.returncode == 0 and screenshot.stat().st_size > 10_000, shot.stderr[-2000:]
