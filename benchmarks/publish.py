"""Publish the asv dashboard of the history so that it loads nothing from outside.

``python benchmarks/publish.py [--html-dir DIR]`` runs ``asv publish`` (into ``DIR``, by
default the ``html_dir`` of ``asv.conf.json``), then copies the third-party scripts the
pages load from CDNs (``benchmarks/vendor``, with their licences) beside them and points
the pages at those copies. A script or stylesheet of an address it has no copy of is an
error naming it: a newer asv that loads another library needs its copy added here.
Serve the folder (``asv preview``, or ``python -m http.server -d DIR``): the pages fetch
their graphs, which browsers refuse from ``file://``.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
VENDOR = Path(__file__).resolve().parent / "vendor"

#: The last part of each address asv 0.6's pages load from a CDN -> the file in ``vendor``.
COPIES = {
    "jquery-3.3.1.min.js": "jquery.min.js",
    "jquery.flot.min.js": "jquery.flot.js",
    "jquery.flot.time.min.js": "jquery.flot.time.js",
    "jquery.flot.selection.min.js": "jquery.flot.selection.js",
    "jquery.flot.categories.min.js": "jquery.flot.categories.js",
    "jquery.flot.orderBars.js": "jquery.flot.orderBars.js",
    "stupidtable.min.js": "stupidtable.min.js",
    "md5.min.js": "md5.min.js",
    "bootstrap.min.js": "bootstrap.min.js",
    "bootstrap.min.css": "bootstrap.min.css",
}

#: A script or stylesheet tag, and the address in it that leaves the folder.
TAG = re.compile(r"<(?:script|link)\b[^>]*>")
EXTERNAL = re.compile(r'\b(src|href)="((?:https?:)?//[^"]+)"')

#: Attributes that pin the CDN's bytes (subresource integrity): the copies are the same
#: libraries, some unminified, so the browser would refuse them with these.
PINNING = re.compile(r'\s(?:integrity|crossorigin|referrerpolicy)="[^"]*"')


def localise(page: str) -> str:
    """Return ``page`` with every external script and stylesheet pointed at ``vendor/``.

    Raises
    ------
    ValueError
        An external script or stylesheet with no copy in :data:`COPIES`.
    """
    def tag(match):
        found = EXTERNAL.search(match.group(0))
        if found is None:
            return match.group(0)
        name = found.group(2).rsplit("/", 1)[-1]
        if name not in COPIES:
            raise ValueError(f"no copy of {found.group(2)} in benchmarks/vendor: add it "
                             "(and its licence) and name it in COPIES")
        local = match.group(0).replace(found.group(0), f'{found.group(1)}="vendor/{COPIES[name]}"')
        return PINNING.sub("", local)

    return TAG.sub(tag, page)


def publish(html_dir: Path | None = None) -> Path:
    """Run ``asv publish`` and make its pages self-contained; return the folder."""
    if html_dir is None:
        html_dir = ROOT / json.loads((ROOT / "asv.conf.json").read_text())["html_dir"]
    html_dir = Path(html_dir).resolve()  # asv runs in the root; the copies go here too
    done = subprocess.run(["asv", "publish", "--no-pull", "--html-dir", str(html_dir)],
                          cwd=ROOT, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"asv publish exited {done.returncode}: {done.stderr[-2000:]}")
    (html_dir / "vendor").mkdir(exist_ok=True)
    for name in [*COPIES.values(), "LICENSES.md"]:
        shutil.copyfile(VENDOR / name, html_dir / "vendor" / name)
    for page in html_dir.glob("*.html"):
        page.write_text(localise(page.read_text(encoding="utf-8")), encoding="utf-8")
    return html_dir


def main(argv=None) -> int:
    """Command line: ``python benchmarks/publish.py [--html-dir DIR]``."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--html-dir", type=Path, default=None,
                        help="where to write the dashboard (default: asv.conf.json's html_dir)")
    args = parser.parse_args(argv)
    try:
        folder = publish(args.html_dir)
    except (RuntimeError, ValueError, OSError) as error:
        print(f"publish: error: {error}", file=sys.stderr)
        return 2
    print(f"wrote {folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
