"""The report page in a real browser: headless Chromium loads every image of index.html."""

import json
import os
import re
import shutil
import subprocess

import pytest
from translucent.reports.report.pipeline import make_report
from translucent.scenes import Camera, load_scene

pytestmark = [pytest.mark.browser, pytest.mark.slow]

#: Executables tried in order (``TRANSLUCENT_CHROMIUM`` first when set).
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")

#: Seconds of virtual time Chromium gives the page to load its images before dumping the DOM.
VIRTUAL_TIME_BUDGET_MS = 10_000

#: Appended to a copy of the page: after ``load`` it writes which images failed into the
#: ``data-image-check`` attribute of <body>, which ``--dump-dom`` prints.
CHECK_SCRIPT = """
<script>
window.addEventListener("load", () => {
  const images = Array.from(document.images);
  const broken = images.filter(i => !(i.complete && i.naturalWidth > 0))
                       .map(i => i.getAttribute("src"));
  document.body.setAttribute("data-image-check",
                             JSON.stringify({total: images.length, broken: broken}));
});
</script>
"""


def _chromium() -> str | None:
    given = os.environ.get("TRANSLUCENT_CHROMIUM")
    if given:
        return shutil.which(given) or (given if os.path.isfile(given) else None)
    for name in CHROMIUM_NAMES:
        found = shutil.which(name)
        if found:
            return found
    return None


@pytest.fixture(scope="module")
def chromium():
    found = _chromium()
    if found is None:
        pytest.skip(f"no headless Chromium found (tried {', '.join(CHROMIUM_NAMES)}; set "
                    "TRANSLUCENT_CHROMIUM or `apt-get install chromium`)")
    return found


def test_every_image_of_the_page_loads_in_chromium(chromium, tmp_path):
    # the Cornell box at 32 x 32: walls, a translucent block, every built method that applies
    scene = load_scene("cornell_block")
    camera = scene.camera
    scene = scene.with_camera(Camera(camera.origin, camera.target, camera.up, camera.fov, 32, 32))
    out = tmp_path / "report"
    make_report([scene], out, baseline=tmp_path / "baseline.json", update_baseline=True,
                serial=True, spp=8, passes=2, progress=False)
    page = (out / "index.html").read_text()
    sources = re.findall(r'<img src="([^"]+)"', page)
    assert len(sources) >= 1
    probe = out / "image_check.html"
    probe.write_text(page.replace("</body>", CHECK_SCRIPT + "</body>"))
    result = subprocess.run(
        [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files",
         f"--virtual-time-budget={VIRTUAL_TIME_BUDGET_MS}", "--dump-dom", probe.as_uri()],
        capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    match = re.search(r'data-image-check="([^"]*)"', result.stdout)
    assert match, "the page's load event never ran: " + result.stdout[:500]
    check = json.loads(match.group(1).replace("&quot;", '"'))
    assert check["total"] == len(sources)
    assert check["broken"] == []


#: The first screen the page must answer its question in: a laptop browser window.
FIRST_SCREEN = (1400, 900)

#: Appended to a copy of the page: the summary table's and the overview plot's boxes, and the
#: scenes the table names, written into ``data-layout`` of <body> for ``--dump-dom``.
LAYOUT_SCRIPT = """
<script>
window.addEventListener("load", () => {
  const box = e => { if (!e) return null; const r = e.getBoundingClientRect();
                     return {left: r.left, top: r.top, right: r.right, bottom: r.bottom}; };
  const plot = document.querySelector("figure.overview img");
  const rows = Array.from(document.querySelectorAll("table.summary tr th a"))
                    .map(a => a.textContent);
  document.body.setAttribute("data-layout", JSON.stringify({
    table: box(document.querySelector("table.summary")), plot: box(plot),
    plot_loaded: !!(plot && plot.complete && plot.naturalWidth > 0), scenes: rows,
    cells_with_times: Array.from(document.querySelectorAll("table.summary td"))
                           .filter(td => td.textContent.includes("vs path tracing")).length}));
});
</script>
"""


def test_the_first_screen_shows_how_wrong_and_how_fast_on_every_default_scene(chromium,
                                                                               tmp_path):
    from translucent.reports.report.pipeline import default_scenes

    out = tmp_path / "report"
    make_report(None, out, baseline=tmp_path / "baseline.json", update_baseline=True,
                progress=False)
    names, _ = default_scenes()
    page = (out / "index.html").read_text()
    probe = out / "layout_check.html"
    probe.write_text(page.replace("</body>", LAYOUT_SCRIPT + "</body>"))
    width, height = FIRST_SCREEN
    common = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
              "--allow-file-access-from-files", f"--window-size={width},{height}",
              f"--virtual-time-budget={VIRTUAL_TIME_BUDGET_MS}"]
    result = subprocess.run(common + ["--dump-dom", probe.as_uri()], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    match = re.search(r'data-layout="([^"]*)"', result.stdout)
    assert match, "the page's load event never ran: " + result.stdout[:500]
    layout = json.loads(match.group(1).replace("&quot;", '"'))
    assert sorted(layout["scenes"]) == sorted(names)
    for part in ("table", "plot"):
        box = layout[part]
        assert box is not None, part
        assert 0 <= box["left"] and box["right"] <= width, (part, box)
        assert 0 <= box["top"] and box["bottom"] <= height, (part, box)
    assert layout["plot_loaded"]
    scored = sum(len(scene["methods"]) - sum(m["metrics"] is None for m in
                                              scene["methods"].values())
                 for scene in json.loads((out / "metrics.json").read_text())["scenes"].values())
    assert layout["cells_with_times"] == scored > 0
    shot = tmp_path / "first_screen.png"
    subprocess.run(common + [f"--screenshot={shot}", (out / "index.html").as_uri()],
                   capture_output=True, timeout=120, check=True)
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
