"""What the hostile-input modules share: small inputs, and one way to run a case.

A case is ``(arguments, files, words)`` or ``(arguments, files, words, options)``:
``files`` are made in a fresh folder before the command runs (text, bytes, or a
:class:`Made` that builds the file itself: a FIFO, a sparse file, a crafted header);
``{d}`` in the arguments is that folder. ``options`` may hold ``env`` (variables set for
the command) and ``memory`` (the bytes the machine is taken to have; default 8 GiB).
:func:`run_case` runs the command in-process, in that folder, and checks what every case
must keep: exit code 2, no traceback, standard error naming each of ``words``, and the
folder exactly as it was (inputs byte for byte, nothing written, nothing half-written, no
temporary left).
"""

import hashlib
import json
import os
import struct
import tempfile
from pathlib import Path

import numpy as np
from translucent.image import Image
from translucent.reports.cli import main
from translucent.scenes import load_scene

#: Files larger than this are compared by size and modification time, not read (a sparse
#: file of a gigabyte must cost nothing).
READ_LIMIT = 1 << 20


class Made:
    """A file a case makes with ``build(path)`` (a node, a sparse file, a crafted header)."""

    def __init__(self, build):
        self.build = build


class CaptureFile(str):
    """A file of the small synthetic capture the ``capture`` fixtures make once."""


def sphere_text(**replacements) -> str:
    """The built-in sphere's scene file, with ``old=new`` text replaced."""
    text = Path(load_scene("sphere").source).read_text(encoding="utf-8")
    for old, new in replacements.items():
        text = text.replace(old, new)
    return text


SPHERE = sphere_text()

#: The sphere at 16 x 16 pixels and a coarse mesh: a render of it costs well under a second.
TINY_SPHERE = SPHERE.replace("width = 96", "width = 16").replace("height = 96", "height = 16") \
    .replace("subdivisions = 4", "subdivisions = 1")


def exr_bytes(size=(16, 16), value=0.5, variance=None, channels=None, header=None) -> bytes:
    """The bytes of a small EXR: the suite's own, or ``channels`` written as another program
    would (no checksum; ``name -> plane`` or ``name -> OpenEXR.Channel``)."""
    import OpenEXR

    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "image.exr")
        if channels is None and header is None:
            rgb = np.full(size + (3,), value, dtype=np.float32)
            Image(rgb, None if variance is None else np.full_like(rgb, variance)).write(path)
        else:
            if channels is None:
                channels = {"RGB": np.full(size + (3,), value, dtype=np.float32)}
            with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION,
                               "type": OpenEXR.scanlineimage, **(header or {})},
                              channels) as exr:
                exr.write(path)
        return Path(path).read_bytes()


def declaring(data: bytes, width: int, height: int) -> bytes:
    """``data`` (an EXR) with its header's data window rewritten to ``width`` x ``height``.

    The pixels stay those of the small image: only a reader that trusts the header before
    it checks the memory needed would allocate for the declared size.
    """
    tag = b"dataWindow\x00box2i\x00"
    at = data.index(tag) + len(tag) + 4
    return data[:at] + struct.pack("<4i", 0, 0, width - 1, height - 1) + data[at + 16:]


def npz_declaring(shape, dtype="<f4", **scalars) -> Made:
    """An ``.npz`` whose ``log_profile`` member declares ``shape`` but holds no data."""
    def build(path):
        import zipfile

        header = {"descr": dtype, "fortran_order": False, "shape": tuple(shape)}
        with zipfile.ZipFile(path, "w") as archive:
            with archive.open("log_profile.npy", "w") as member:
                np.lib.format.write_array_header_1_0(member, header)
            for name, value in scalars.items():
                with archive.open(f"{name}.npy", "w") as member:
                    np.lib.format.write_array(member, np.array(value))
    return Made(build)


def sparse(size: int) -> Made:
    """A sparse file of ``size`` bytes (holes: no disk is used)."""
    def build(path):
        with open(path, "wb") as handle:
            handle.truncate(size)
    return Made(build)


def written(size: int) -> Made:
    """A file of ``size`` bytes all on disk (no holes): a long OBJ comment line."""
    def build(path):
        path.write_bytes(b"#" + b" " * (size - 2) + b"\n")
    return Made(build)


def nested_json(depth: int) -> str:
    """A JSON value of ``depth`` nested arrays."""
    return "[" * depth + "]" * depth


def tree(folder: Path) -> dict:
    """What ``folder`` holds: every entry, with its bytes (or size and time when large)."""
    found = {}
    for path in sorted(folder.rglob("*")):
        stat = path.lstat()
        key = str(path.relative_to(folder))
        if path.is_symlink() or not path.is_file():
            found[key] = (oct(stat.st_mode), os.readlink(path) if path.is_symlink() else None)
        elif stat.st_size > READ_LIMIT:
            found[key] = (stat.st_size, stat.st_mtime_ns)
        else:
            found[key] = hashlib.sha256(path.read_bytes()).hexdigest()
    return found


def make_files(folder: Path, files: dict, captured: dict | None = None) -> None:
    """Write ``files`` into ``folder`` (see the module docstring)."""
    for name, content in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, Made):
            content.build(path)
            continue
        if isinstance(content, CaptureFile):
            content = captured[str(content)]
        path.write_bytes(content if isinstance(content, bytes) else content.encode("utf-8"))


def run_case(case, folder: Path, monkeypatch, capsys, captured: dict | None = None):
    """Run one case in ``folder`` and check what every case keeps; return ``(out, err)``."""
    from translucent import resources

    arguments, files, words = case[:3]
    options = case[3] if len(case) > 3 else {}
    # the memory cases do not depend on the machine the tests run on
    memory = options.get("memory", 8 * 2**30)
    monkeypatch.setattr(resources, "available_memory", lambda: memory)
    for name, value in options.get("env", {}).items():
        monkeypatch.setenv(name, value.replace("{d}", str(folder)))
    make_files(folder, files, captured)
    before = tree(folder)
    monkeypatch.chdir(folder)
    code = main([part.replace("{d}", str(folder)) for part in arguments])
    out, err = capsys.readouterr()
    assert code == 2, (out, err)
    assert "Traceback" not in err + out
    for word in words:
        assert word.replace("{d}", str(folder)) in err, (word, err)
    assert tree(folder) == before, "files were changed, written or left behind"
    return out, err


def json_record(text: str) -> dict:
    """The JSON object ``--json`` wrote (the last one in ``text``)."""
    return json.loads(text[text.rindex('{\n  "command"'):])
