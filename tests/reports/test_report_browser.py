"""The report page in a real browser: headless Chromium loads every image of index.html."""

import json
import os
import re
import shutil
import subprocess

import pytest
from translucent.reports.report import make_report
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
