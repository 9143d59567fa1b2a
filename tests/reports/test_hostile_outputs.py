"""Outputs that would destroy an input, and outputs that are streams.

An output path equal to an input (directly, through a symbolic or a hard link, or as a
name derived from another: an error map, the image beside a sidecar) is refused before any
work, with exit 2 and every input byte for byte unchanged (:mod:`hostile` runs the cases).
A FIFO or a character device given as an output is written as a stream and stays what it
was; a name taken from a scene never puts an output outside the working folder.
"""

import os
import stat
import subprocess
import sys
import threading

import pytest
from hostile import (
    TINY_SPHERE,
    CaptureFile,
    Made,
    exr_bytes,
    json_record,
    make_files,
    run_case,
    tree,
)
from translucent.image import read_exr
from translucent.reports.cli import main

EXR = exr_bytes()

#: A capture's sidecar and image (made once by the ``capture`` fixture).
CAPTURE = {"c.json": CaptureFile("small.json"), "small.exr": CaptureFile("small.exr")}

#: The tiny sphere lit by an environment map beside it as well.
ENVIRONMENT_SCENE = TINY_SPHERE + '\n[[lights]]\ntype = "image_env"\nfile = "env.exr"\n'
ENVIRONMENT = {"s.toml": ENVIRONMENT_SCENE, "env.exr": exr_bytes((8, 16))}


def _link(target: str, *, hard: bool = False) -> Made:
    """A symbolic (or hard) link to ``target``, a file of the same folder."""
    def build(path):
        if hard:
            os.link(path.parent / target, path)
        else:
            os.symlink(target, path)
    return Made(build)


#: kind -> (arguments, files, words stderr must hold): each an output that is an input
CASES = {
    "compare: --json over the reference": (["compare", "{d}/ref.exr", "{d}/a.exr", "--json",
                                            "{d}/ref.exr"], {"ref.exr": EXR, "a.exr": EXR},
                                           ["--json", "ref.exr", "input reference"]),
    "compare: --json over the test image": (["compare", "{d}/ref.exr", "{d}/a.exr", "--json",
                                             "{d}/a.exr"], {"ref.exr": EXR, "a.exr": EXR},
                                            ["--json", "a.exr", "input test"]),
    "compare: --json through a symbolic link to the reference": (
        ["compare", "{d}/ref.exr", "{d}/a.exr", "--json", "{d}/record.json"],
        {"ref.exr": EXR, "a.exr": EXR, "record.json": _link("ref.exr")}, ["--json", "ref.exr"]),
    "compare: --json a hard link of the reference": (
        ["compare", "{d}/ref.exr", "{d}/a.exr", "--json", "{d}/record.json"],
        {"ref.exr": EXR, "a.exr": EXR, "record.json": _link("ref.exr", hard=True)},
        ["--json", "record.json"]),
    "compare: an error map over the reference": (["compare", "{d}/A_flip.exr", "{d}/A.exr"],
                                                 {"A_flip.exr": EXR, "A.exr": EXR},
                                                 ["error map", "A_flip.exr", "--maps"]),
    "compare: --maps over the reference": (["compare", "{d}/maps/t_ssim.exr", "{d}/t.exr",
                                            "--maps", "{d}/maps"],
                                           {"maps/t_ssim.exr": EXR, "t.exr": EXR},
                                           ["--maps", "t_ssim.exr"]),
    "compare: --json over an error map": (["compare", "{d}/ref.exr", "{d}/a.exr", "--json",
                                           "{d}/a_flip.png"], {"ref.exr": EXR, "a.exr": EXR},
                                          ["a_flip.png", "--json"]),
    "render: --out and --json one file": (["render", "{d}/s.toml", "--out", "{d}/o.exr",
                                           "--json", "{d}/o.exr"], {"s.toml": TINY_SPHERE},
                                          ["--out", "--json", "o.exr"]),
    "render: --out over the environment map": (["render", "{d}/s.toml", "--out",
                                                "{d}/env.exr"], ENVIRONMENT,
                                               ["--out", "env.exr"]),
    "render: --json over the scene file": (["render", "{d}/s.toml", "--json", "{d}/s.toml"],
                                           {"s.toml": TINY_SPHERE}, ["--json", "s.toml"]),
    "approx: --out over the environment map": (["approx", "prt", "{d}/s.toml", "--out",
                                                "{d}/env.exr"], ENVIRONMENT,
                                               ["--out", "env.exr"]),
    "export: --json over the scene file": (["export", "{d}/s.toml", "--out", "{d}/e", "--json",
                                            "{d}/s.toml"], {"s.toml": TINY_SPHERE},
                                           ["--json", "s.toml"]),
    "capture import: the capture's image over the photo": (
        ["capture-import", "{d}/photo.exr", "--pixel-size-mm", "0.1", "--out",
         "{d}/photo.json"], {"photo.exr": EXR}, ["--out", "photo.exr", "input photo"]),
    "capture import: the capture's image over the dark frame": (
        ["capture-import", "{d}/photo.exr", "--dark", "{d}/dark.exr", "--pixel-size-mm", "0.1",
         "--out", "{d}/dark.json"], {"photo.exr": EXR, "dark.exr": EXR},
        ["--out", "dark.exr", "--dark"]),
    "capture import: the capture's image over the beam photo": (
        ["capture-import", "{d}/photo.exr", "--beam-image", "{d}/beam.exr", "--pixel-size-mm",
         "0.1", "--out", "{d}/beam.json"], {"photo.exr": EXR, "beam.exr": EXR},
        ["--out", "beam.exr", "--beam-image"]),
    "capture import: --json over the photo": (["capture-import", "{d}/photo.exr",
                                               "--pixel-size-mm", "0.1", "--out", "{d}/c.json",
                                               "--json", "{d}/photo.exr"], {"photo.exr": EXR},
                                              ["--json", "photo.exr"]),
    "fit: --json over the capture": (["fit", "{d}/c.json", "--out", "{d}/fit", "--json",
                                      "{d}/c.json"], CAPTURE, ["--json", "c.json"]),
    "fit: --json over the capture's image": (["fit", "{d}/c.json", "--out", "{d}/fit",
                                              "--json", "{d}/small.exr"], CAPTURE,
                                             ["--json", "small.exr", "input image"]),
    "capture: --json over the material file": (["capture", "{d}/m.toml", "--out", "{d}/c.json",
                                                "--json", "{d}/m.toml"], {"m.toml": "x = 1\n"},
                                               ["--json", "m.toml"]),
    "report: --images inside the --out it replaces": (
        ["report", "--images", "{d}/r/images", "--out", "{d}/r"],
        {"r/metrics.json": "{}", "r/images/other/sphere.exr": EXR}, ["--out", "--images"]),
}


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """The bytes of a 32 x 32 dipole capture: sidecar and image."""
    folder = tmp_path_factory.mktemp("capture")
    assert main(["capture", "skin1", "--generator", "dipole", "--size", "32", "--out",
                 str(folder / "small.json"), "--quiet"]) == 0
    return {name: (folder / name).read_bytes() for name in ("small.json", "small.exr")}


@pytest.mark.parametrize("kind", sorted(CASES))
def test_an_output_never_replaces_an_input(kind, tmp_path, capsys, monkeypatch, capture):
    folder = tmp_path / "work"
    folder.mkdir()
    run_case(CASES[kind], folder, monkeypatch, capsys, capture)


# ---------------------------------------------------------------------- streams


def _compare_into(target, folder) -> int:
    make_files(folder, {"ref.exr": EXR, "a.exr": EXR})
    return main(["compare", str(folder / "ref.exr"), str(folder / "a.exr"), "--no-maps",
                 "--json", str(target)])


def test_json_into_a_fifo_is_written_as_a_stream(tmp_path, capsys):
    fifo = tmp_path / "record.fifo"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    try:
        code = _compare_into(fifo, tmp_path)
    finally:
        if reader.is_alive() and not received:  # nothing came: let the reader end
            with open(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK), "wb"):
                pass
        reader.join(timeout=30)
    assert code == 0, capsys.readouterr().err
    assert stat.S_ISFIFO(os.stat(fifo).st_mode), "the FIFO was replaced"
    assert json_record(received[0].decode())["exit_code"] == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "record.fifo", "ref.exr"]


def test_json_into_a_character_device_is_written_as_a_stream(tmp_path, capsys):
    device = tmp_path / "null"
    try:  # the machine's null device, made here: never the machine's own node
        os.mknod(device, stat.S_IFCHR | 0o666, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("making a device node needs root")
    assert _compare_into(device, tmp_path) == 0, capsys.readouterr().err
    assert stat.S_ISCHR(os.stat(device).st_mode), "the device was replaced by a file"


def test_json_into_a_descriptor_of_the_process_keeps_the_link(tmp_path, capfd):
    link = tmp_path / "stdout"  # what /dev/stdout is
    os.symlink("/proc/self/fd/1", link)
    assert _compare_into(link, tmp_path) == 0
    assert os.readlink(link) == "/proc/self/fd/1", "the link was replaced by a file"
    assert json_record(capfd.readouterr().out)["command"] == "compare"


def test_an_image_into_a_fifo_is_written_as_a_stream(tmp_path, capsys):
    fifo = tmp_path / "image.exr"
    os.mkfifo(fifo)
    (tmp_path / "s.toml").write_text(TINY_SPHERE)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    try:
        code = main(["render", str(tmp_path / "s.toml"), "--spp", "1", "--passes", "2",
                     "--out", str(fifo), "--no-cache"])
    finally:
        if reader.is_alive() and not received:
            with open(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK), "wb"):
                pass
        reader.join(timeout=60)
    assert code == 0, capsys.readouterr().err
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    (tmp_path / "copy.exr").write_bytes(received[0])
    assert read_exr(tmp_path / "copy.exr").shape == (16, 16)


def test_a_full_standard_output_ends_with_one_line(tmp_path):
    full = tmp_path / "full"
    try:  # a full device of our own (what /dev/full is), never the machine's
        os.mknod(full, stat.S_IFCHR | 0o666, os.makedev(1, 7))
    except PermissionError:
        pytest.skip("making a device node needs root")
    with open(full, "wb") as sink:
        done = subprocess.run([sys.executable, "-c", "from translucent.reports.cli import "
                               "entry_point; entry_point()", "scenes"], stdout=sink,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        "translucent scenes: error: standard output: cannot be written (No space left on "
        "device)"]


# ---------------------------------------------------------------------- names from files


def test_a_scene_name_never_puts_an_output_outside_the_working_folder(tmp_path, monkeypatch,
                                                                      capsys):
    outside = tmp_path / "outside"
    work = outside / "deeper" / "work"
    work.mkdir(parents=True)
    (work / "s.toml").write_text(TINY_SPHERE.replace('name = "sphere"\ndescription',
                                                     'name = "../../escaped\\u0000"\n'
                                                     'description'))
    monkeypatch.chdir(work)
    before = tree(outside)
    assert main(["export", "s.toml"]) == 0, capsys.readouterr().err
    assert main(["render", "s.toml", "--spp", "1", "--passes", "2", "--no-cache"]) == 0
    made = set(tree(outside)) - set(before)
    assert made and all(name.startswith("deeper/work/escaped_") for name in made), made


def test_safe_file_names():
    from translucent.atomic import SAFE_NAME_LENGTH, safe_file_name

    assert safe_file_name("../..") == "unnamed"
    assert safe_file_name("a/b\x00c") == "a_b_c"
    assert safe_file_name(".hidden") == "hidden"
    assert len(safe_file_name("n" * 5000)) == SAFE_NAME_LENGTH


# ---------------------------------------------------------------------- long names


def test_render_writes_an_image_of_the_longest_name(tmp_path, capsys):
    (tmp_path / "s.toml").write_text(TINY_SPHERE)
    name = "n" * 251 + ".exr"  # 255 bytes: its temporary file's name must fit too
    assert main(["render", str(tmp_path / "s.toml"), "--spp", "1", "--passes", "2",
                 "--no-cache", "--no-progress", "--quiet", "--out",
                 str(tmp_path / name)]) == 0, capsys.readouterr().err
    assert read_exr(tmp_path / name).shape == (16, 16)
    assert sorted(p.name for p in tmp_path.iterdir()) == [name, "s.toml"]


def test_fit_writes_into_a_folder_of_the_longest_name(tmp_path, monkeypatch, capsys):
    from translucent.atomic import atomic_write_text
    from translucent.fitting import fit

    def fit_capture(capture, *, models, out_dir, **options):  # what the fit writes
        atomic_write_text(out_dir / "dipole_summary.json", "{}")
        return {}

    monkeypatch.setattr(fit, "fit_capture", fit_capture)
    out = tmp_path / ("f" * 255)  # its staging folder's name must fit too
    assert main(["fit", str(tmp_path / "c.json"), "--out", str(out), "--quiet"]) == 0, \
        capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == [out.name]
    assert (out / "dipole_summary.json").read_text() == "{}"
