"""Output where nothing can be written is an input error before any work, never a traceback.

``/proc`` refuses new files to every user (root included) on every Linux machine; the
check is tried, not guessed from permission bits (a read-only mount says the same).
"""

import errno
import os
import shutil
import subprocess
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


# ---------------------------------------------------------------------- a full disk
#
# The fault is injected where the bytes are written (the writer raises as it does on a full
# disk); each command must end with exit 2 and one line naming the output, and leave the
# folder as it was: no file, no temporary, no staging folder, no folder made for the output.


def _no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, "No space left on device")


def _failing_after(count: int, fail):
    """``Path.write_bytes`` that writes ``count`` times, then fails as ``fail`` does."""
    real = Path.write_bytes
    calls = []

    def write_bytes(self, data):
        calls.append(self)
        if len(calls) > count:
            fail()
        return real(self, data)

    return write_bytes


class _FullExr:
    """``OpenEXR.File`` whose write leaves half a file and fails as OpenEXR does on a full
    disk (reading, and everything else, is the real one's)."""

    real = None

    def __init__(self, *args, **kwargs):
        self._file = self.real(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self._file, name)

    def __enter__(self):
        self._file.__enter__()
        return self

    def __exit__(self, *exc):
        return self._file.__exit__(*exc)

    def write(self, path):
        Path(path).write_bytes(b"v/1\x01half")
        raise RuntimeError(f'Failed to write pixel data to image file "{path}". No space left '
                           "on device.")


@pytest.fixture
def full_exr(monkeypatch):
    import OpenEXR

    monkeypatch.setattr(_FullExr, "real", OpenEXR.File)
    monkeypatch.setattr(OpenEXR, "File", _FullExr)


@pytest.fixture
def work(tmp_path, monkeypatch):
    """A working folder holding a tiny scene and two tiny images, its content recorded."""
    from hostile import TINY_SPHERE, exr_bytes, tree

    (tmp_path / "s.toml").write_text(TINY_SPHERE)
    (tmp_path / "ref.exr").write_bytes(exr_bytes())
    (tmp_path / "test.exr").write_bytes(exr_bytes(value=0.25))
    monkeypatch.chdir(tmp_path)
    return tmp_path, tree(tmp_path)


def _ends_cleanly(code, capsys, work, *words):
    from hostile import tree

    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "No space left on device" in err and all(word in err for word in words), err
    assert tree(work[0]) == work[1], "something was left behind"


def test_a_full_disk_under_render_ends_with_one_line(work, full_exr, capsys):
    code = main(["render", "s.toml", "--spp", "1", "--passes", "2", "--no-cache", "--out",
                 "new/deeper/s.exr", "--no-progress"])
    _ends_cleanly(code, capsys, work, "--out", "new/deeper/s.exr")


def test_a_full_disk_under_compare_maps_ends_with_one_line(work, full_exr, capsys):
    code = main(["compare", "ref.exr", "test.exr", "--maps", "new/maps"])
    _ends_cleanly(code, capsys, work, "new/maps/test_flip.exr")


def test_a_full_disk_under_compare_after_some_maps_ends_with_one_line(work, monkeypatch,
                                                                      capsys):
    from matplotlib import image

    def imsave(path, *args, **kwargs):  # the first map's EXR is written, then its PNG fails
        Path(path).write_bytes(b"\x89PNG half")
        _no_space()

    monkeypatch.setattr(image, "imsave", imsave)
    code = main(["compare", "ref.exr", "test.exr", "--maps", "maps"])
    _ends_cleanly(code, capsys, work, "maps/test_flip.png")


def test_a_full_disk_under_export_ends_with_one_line(work, monkeypatch, capsys):
    # the meshes are written (by Mitsuba) before the XML fails
    monkeypatch.setattr(Path, "write_bytes", _failing_after(0, _no_space))
    code = main(["export", "s.toml", "--out", "new/e"])
    _ends_cleanly(code, capsys, work, "--out", "new/e", "sphere.xml")


def test_a_full_disk_under_export_in_mitsubas_words_ends_with_one_line(work, monkeypatch,
                                                                       capsys):
    from translucent.reference import mitsuba_export

    def failing(self, parent, key, mesh, props):  # as Mitsuba's writer fails: half a file
        path, _ = self._file("meshes", key, ".ply")
        path.write_text("ply\nformat binary_little_endian 1.0\n")
        raise RuntimeError(f'write_ply(): I/O error while writing "{path}": No space left on '
                           "device")

    monkeypatch.setattr(mitsuba_export._Writer, "mesh", failing)
    code = main(["export", "s.toml", "--out", "e"])
    _ends_cleanly(code, capsys, work, "--out", "e")


def test_a_full_disk_under_fit_ends_with_one_line(work, monkeypatch, capsys):
    from translucent.atomic import atomic_write_text
    from translucent.fitting import fit

    def fit_capture(capture, *, models, out_dir, **options):
        atomic_write_text(out_dir / "dipole_summary.json", "{}")
        atomic_write_text(out_dir / "dipole_material.toml", "never written")

    monkeypatch.setattr(fit, "fit_capture", fit_capture)
    monkeypatch.setattr(Path, "write_bytes", _failing_after(1, _no_space))
    code = main(["fit", "c.json", "--out", "new/fit"])
    _ends_cleanly(code, capsys, work, "--out", "new/fit", "dipole_material.toml")


def test_a_full_disk_under_json_ends_with_one_line(work, monkeypatch, capsys):
    monkeypatch.setattr(Path, "write_bytes", _no_space)
    code = main(["compare", "ref.exr", "test.exr", "--no-maps", "--json", "record.json"])
    _ends_cleanly(code, capsys, work, "record.json")


def test_a_full_disk_met_outside_any_writer_ends_with_one_line(work, monkeypatch, capsys):
    from translucent.reports.commands import scenes

    def failing(args):
        raise OSError(errno.ENOSPC, "No space left on device", "somewhere.txt")

    monkeypatch.setattr(scenes, "run", failing)
    _ends_cleanly(main(["scenes"]), capsys, work, "somewhere.txt")


# ---------------------------------------------------------------------- a real full disk


@pytest.fixture(scope="module")
def full_disk(tmp_path_factory):
    """A tmpfs of 64 KiB with no byte left (root only: skipped where none can be mounted)."""
    folder = tmp_path_factory.mktemp("full")
    if not hasattr(os, "geteuid") or os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs needs root")
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(folder)],
                             capture_output=True)
    if mounted.returncode:
        pytest.skip(f"no tmpfs can be mounted here: {mounted.stderr.decode().strip()}")
    try:
        fd = os.open(folder / "filler", os.O_WRONLY | os.O_CREAT)
        try:
            while True:
                os.write(fd, b"x" * 4096)
        except OSError:  # full
            pass
        finally:
            os.close(fd)
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], check=False)


FULL = {
    "render": ["render", "s.toml", "--spp", "1", "--passes", "2", "--no-cache", "--out",
               "{full}/new/s.exr", "--no-progress"],
    "compare --maps": ["compare", "ref.exr", "test.exr", "--maps", "{full}/new/maps"],
    "compare --json": ["compare", "ref.exr", "test.exr", "--no-maps", "--json",
                       "{full}/record.json"],
    "export": ["export", "s.toml", "--out", "{full}/new/e"],
}


@pytest.mark.parametrize("name", list(FULL))
def test_a_real_full_disk_ends_with_one_line(name, full_disk, work, capsys):
    from hostile import tree

    before = tree(full_disk)
    code = main([part.replace("{full}", str(full_disk)) for part in FULL[name]])
    _ends_cleanly(code, capsys, work, str(full_disk))
    assert tree(full_disk) == before
