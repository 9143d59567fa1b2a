"""Output where nothing can be written is an input error before any work, never a traceback.

``/proc`` refuses new files to every user (root included) on every Linux machine; the
check is tried, not guessed from permission bits (a read-only mount says the same).
"""

import sys
from pathlib import Path

import pytest
from translucent.reports.cli import main

UNWRITABLE = Path("/proc")

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="/proc is Linux's")


@pytest.fixture(scope="module")
def an_image(tmp_path_factory):
    import numpy as np
    from translucent.image import Image

    path = tmp_path_factory.mktemp("image") / "grey.exr"
    Image(np.full((12, 12, 3), 0.5, np.float32)).write(path)
    return path


COMMANDS = {
    "render": lambda image: ["render", "sphere", "--spp", "1", "--passes", "1", "--out",
                             str(UNWRITABLE / "sphere.exr")],
    "render into a folder to be made": lambda image: [
        "render", "sphere", "--spp", "1", "--passes", "1", "--out",
        str(UNWRITABLE / "new" / "sphere.exr")],
    "capture": lambda image: ["capture", "Skin1", "--size", "32", "--out",
                              str(UNWRITABLE / "capture.exr")],
    "compare --maps": lambda image: ["compare", str(image), str(image), "--maps",
                                     str(UNWRITABLE / "maps")],
    "stress --json": lambda image: ["stress", "--only", "fresnel", "--json",
                                    str(UNWRITABLE / "stress.json")],
    "scenes --json": lambda image: ["scenes", "--json", str(UNWRITABLE / "scenes.json")],
    "export": lambda image: ["export", "sphere", "--out", str(UNWRITABLE / "sphere_files")],
    "report": lambda image: ["report", "sphere", "--methods", "splatting", "--out",
                             str(UNWRITABLE / "report")],
    "approx": lambda image: ["approx", "splatting", "sphere", "--out",
                             str(UNWRITABLE / "sphere.exr")],
}


@pytest.mark.parametrize("name", list(COMMANDS))
def test_unwritable_output_is_refused_before_work(name, an_image, capsys):
    code = main(COMMANDS[name](an_image))
    err = capsys.readouterr().err
    assert code == 2, err
    assert f"cannot write in {UNWRITABLE}" in err
    assert "Traceback" not in err
