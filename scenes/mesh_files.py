"""Mesh files: reading OBJ, PLY, STL, OFF and the suite's own ``.npz``, and writing them.

A file is checked before it is parsed (its size against the memory a parser takes, sparse
files, the counts a PLY or OFF header declares against the lines the file holds) and its
coordinates after (finite, within float32's range), so that a bad file is an
:class:`~translucent.errors.InputError` naming the file, the field and the value.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from .scene import Mesh

__all__ = ["MESH_FILE_SUFFIXES", "load_mesh", "save_mesh"]

#: File suffixes :func:`load_mesh` reads: ``.npz`` is the suite's own lossless format
#: (written by :func:`save_mesh`), the others are read through trimesh.
MESH_FILE_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".npz")


#: Memory that reading a mesh file takes per byte of the file, at most: trimesh's text
#: parsers hold the text, its split tokens and the arrays. Peak traced allocations
#: measured on a 12.5 MB icosphere (subdivision 7): 6.3 bytes a byte as OBJ, 15.3 as ASCII
#: PLY; 16 leaves room.
MESH_READ_BYTES_PER_FILE_BYTE = 16

#: Files above this size whose bytes on disk are under 1/64 of their length are refused as
#: sparse (mostly holes); compression on disk shrinks mesh text far less than that.
SPARSE_CHECK_BYTES = 1 << 20


#: Header lines of a PLY read for its declared counts before giving up (the reader then
#: says why it cannot read the file).
PLY_HEADER_LINES = 10000


def load_mesh(path, *, name: str | None = None) -> Mesh:
    """Read a triangle mesh from an OBJ, PLY, STL or OFF file (through trimesh) or an NPZ.

    Polygons are triangulated, nothing is merged or repaired: geometry the suite cannot
    use is rejected rather than silently fixed. An ``.npz`` written by :func:`save_mesh`
    comes back exactly (normals, uv and grid shape included).

    Parameters
    ----------
    path : str or os.PathLike
        The file; its units are the scene's.
    name : str, optional
        The mesh's name (default: the file's stem).

    Returns
    -------
    Mesh
        From OBJ/PLY/STL/OFF the vertex normals are area-weighted face normals and
        ``uv`` is kept when the file has one texture coordinate per vertex.

    Raises
    ------
    InputError
        Missing or unreadable file (a FIFO or a device too), unsupported suffix, a count
        in a PLY or OFF header that the file does not hold, no triangles, NaN/Inf vertices
        or ones beyond float32's range, zero-area faces; the message names the file (and
        the header line or the line of the value, for a text file).
    """
    from ..atomic import check_input_file
    from ..resources import check_memory, format_bytes

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_FILE_SUFFIXES:
        raise InputError(f"unsupported mesh file; valid suffixes: {', '.join(MESH_FILE_SUFFIXES)}",
                         file=path, field="file", value=path.suffix)
    check_input_file(path, "file", what="file")
    found = path.stat()
    size = found.st_size
    # before a byte is parsed: a file of holes, or one too large to hold, is refused now
    on_disk = getattr(found, "st_blocks", None)
    if on_disk is not None and size > SPARSE_CHECK_BYTES and on_disk * 512 * 64 < size:
        raise InputError(f"is a sparse file: {format_bytes(on_disk * 512)} of its "
                         f"{format_bytes(size)} are on disk, the rest are holes (zeros never "
                         "written), not a mesh", file=path, field="file", value=str(path))
    check_memory(size * MESH_READ_BYTES_PER_FILE_BYTE, what=f"reading a mesh file of "
                 f"{format_bytes(size)}", file=path, field="file", value=str(path))
    try:
        arrays = _read_npz(path) if suffix == ".npz" else _read_trimesh(path)
    except InputError:
        raise
    except ImportError as error:  # trimesh reaches for an optional module (an encoding guess)
        raise InputError(f"not a readable mesh: its reader needs the module {error.name}, "
                         "which is not installed (a text STL in another encoding than ASCII "
                         "or UTF-8?); convert it to binary STL, PLY, OBJ or .npz", file=path,
                         field="file", value=str(path)) from None
    except Exception as error:  # readers raise many types on malformed files
        raise InputError(f"not a readable mesh ({error})", file=path) from error
    if len(arrays["faces"]) == 0:
        # a reader that guesses a text file's encoding may return nothing instead of failing
        raise InputError("not a readable mesh: no triangle was read from it; if it holds "
                         "some, convert it to binary STL, PLY, OBJ or .npz", file=path,
                         field="faces", value=0)
    if suffix in (".obj", ".ply", ".off", ".stl"):
        _refuse_float32_overflow_line(path, suffix, arrays["vertices"])
    try:
        return Mesh(**arrays, name=name or path.stem)
    except InputError as error:
        raise InputError(error.reason, file=path, field=error.field, value=error.value) \
            from error


def _read_trimesh(path: Path) -> dict:
    # a header may declare more than the file holds; the readers would take what is there
    suffix = path.suffix.lower()
    if suffix == ".ply":
        _check_ply_counts(path)
    elif suffix == ".off":
        _check_off_counts(path)
    import trimesh

    loaded = trimesh.load(str(path), force="mesh", process=False)
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    faces = np.asarray(getattr(loaded, "faces", np.zeros((0, 3), dtype=np.int64)))
    uv = getattr(getattr(loaded, "visual", None), "uv", None)
    if uv is not None and len(uv) != len(vertices):
        uv = None
    return {"vertices": vertices, "faces": faces, "uv": uv}


def _content_lines(handle, first: int = 1):
    """Yield ``(number, text)`` of each line of ``handle`` that holds more than blanks."""
    for number, line in enumerate(handle, start=first):
        if line.strip():
            yield number, line


def _ply_header(path: Path) -> tuple[bool, list[tuple[str, str, int]], int] | None:
    """``(ascii, [(element, count text, line)], end_header line)`` of a PLY, or None.

    None where the file does not begin as a PLY or its header does not end within
    :data:`PLY_HEADER_LINES` lines: the reader then says what is wrong.
    """
    with open(path, encoding="utf-8", errors="replace") as handle:
        if handle.readline(16).strip() != "ply":
            return None
        ascii_format, elements = False, []
        for number, line in _content_lines(handle, first=2):
            words = line.split()
            if words[0] == "format":
                ascii_format = words[1:2] == ["ascii"]
            elif words[0] == "element" and len(words) >= 3:
                elements.append((words[1], words[2], number))
            elif words[0] == "end_header":
                return ascii_format, elements, number
            if number > PLY_HEADER_LINES:
                return None
    return None


def _declared_count(path: Path, text: str, field: str) -> int:
    """Return a count a header declares (``text``) as an integer >= 0."""
    try:
        count = int(text)
    except ValueError:
        count = -1
    if count < 0:
        raise InputError("a count must be a whole number >= 0", file=path, field=field,
                         value=text)
    return count


def _held_lines(path: Path, skip: int, needed: int, *, comments: bool = False) -> int:
    """Count the lines holding more than blanks after the first ``skip``, up to ``needed``.

    A file that holds enough is not read further.
    """
    held = 0
    with open(path, encoding="utf-8", errors="replace") as handle:
        for number, line in enumerate(handle, start=1):
            if number <= skip:
                continue
            if (line.split("#", 1)[0] if comments else line).strip():
                held += 1
                if held >= needed:
                    break
    return held


def _refuse_short(path: Path, declared: list[tuple[str, int, str]], held: int,
                  where: str) -> None:
    """Refuse the first count of ``declared`` that the ``held`` lines do not reach.

    ``declared`` is ``(what, count, field)`` of each kind of line, in file order.
    """
    before = 0
    for what, count, field in declared:
        if held < before + count:
            have = max(held - before, 0)
            raise InputError(f"declared in the {where}, but the file holds only {have} "
                             f"{what} line{'' if have == 1 else 's'}", file=path, field=field,
                             value=count)
        before += count


def _check_ply_counts(path: Path) -> None:
    """Refuse an ASCII PLY whose header declares more elements than the file has lines.

    The reader takes one line per element and keeps what is there, so a header declaring
    ten million faces over two would pass as a mesh of two. A binary PLY of the wrong
    length is refused by the reader itself.
    """
    header = _ply_header(path)
    if header is None or not header[0]:
        return
    _, elements, end = header
    declared = [(name, _declared_count(path, text, f"element {name} (line {number})"),
                 f"element {name}") for name, text, number in elements]
    needed = sum(count for _, count, _ in declared)
    _refuse_short(path, declared, _held_lines(path, end, needed), "PLY header")


def _check_off_counts(path: Path) -> None:
    """Refuse an OFF whose header counts more vertices or faces than the file has lines."""
    with open(path, encoding="utf-8", errors="replace") as handle:
        # what the reader does: comments dropped, the counts follow the OFF keyword
        found = None
        for number, line in _content_lines(handle):
            text = line.split("#", 1)[0]
            if found is None:
                if "OFF" not in text:
                    if text.strip():
                        return  # not an OFF file: the reader says so
                    continue
                text = text.split("OFF", 1)[1]
                found = number
            if text.strip():
                words, counts_line = text.split(), number
                break
        else:
            return
    if len(words) < 2:
        return  # a malformed count line: the reader says so
    declared = [(what, _declared_count(path, text, f"{what} count (line {counts_line})"),
                 f"{what} count (line {counts_line})")
                for what, text in zip(("vertex", "face"), words[:2], strict=True)]
    needed = sum(count for _, count, _ in declared)
    _refuse_short(path, declared, _held_lines(path, counts_line, needed, comments=True),
                  "OFF header")


def _refuse_float32_overflow_line(path: Path, suffix: str, vertices: np.ndarray) -> None:
    """Name the line of a text mesh file that holds a coordinate beyond float32's range.

    The renderers hold positions as float32, where such a value becomes infinite:
    :class:`Mesh` refuses it by vertex, this says where in the file it is written.
    """
    from .scene import FLOAT32_MAX

    vertices = np.asarray(vertices, dtype=np.float64)
    beyond = set(vertices[np.isfinite(vertices) & (np.abs(vertices) > FLOAT32_MAX)].tolist())
    if not beyond:
        return
    with open(path, encoding="utf-8", errors="replace") as handle:
        for number, line in _content_lines(handle):
            words = line.split()
            if suffix == ".obj":  # positions only: "v x y z [w or colour]"
                if words[0] != "v":
                    continue
                words = words[1:4]
            for word in words:
                try:
                    value = float(word)
                except ValueError:
                    continue
                if value in beyond:
                    raise InputError(f"a coordinate beyond float32's range "
                                     f"(+-{FLOAT32_MAX:.7g}): the renderers hold positions "
                                     "in float32, where it would be infinite", file=path,
                                     field=f"line {number}", value=value)


def _read_npz(path: Path) -> dict:
    with np.load(path, allow_pickle=False) as data:
        missing = {"vertices", "faces"} - set(data.files)
        if missing:
            raise InputError(f"an NPZ mesh needs arrays {sorted(missing)}", file=path,
                             field="arrays", value=sorted(data.files))
        arrays = {key: np.array(data[key]) for key in ("vertices", "faces", "normals", "uv")
                  if key in data.files}
        if "grid_shape" in data.files:
            arrays["grid_shape"] = tuple(int(n) for n in data["grid_shape"])
    return arrays


def save_mesh(mesh: Mesh, path) -> Path:
    """Write ``mesh`` atomically; the suffix picks the format.

    ``.npz`` keeps everything exactly, ``.obj`` and ``.ply`` (through trimesh) keep
    positions and faces.

    Parameters
    ----------
    mesh : Mesh
    path : str or os.PathLike
        Target file; its suffix picks the format.

    Returns
    -------
    pathlib.Path
    """
    from ..atomic import atomic_path

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".npz", ".obj", ".ply"):
        raise InputError("mesh files are written as .npz, .obj or .ply", file=path,
                         field="file", value=path.suffix)
    with atomic_path(path) as tmp:
        if suffix == ".npz":
            arrays = {"vertices": mesh.vertices, "faces": mesh.faces, "normals": mesh.normals}
            if mesh.uv is not None:
                arrays["uv"] = mesh.uv
            if mesh.grid_shape is not None:
                arrays["grid_shape"] = np.asarray(mesh.grid_shape, dtype=np.int64)
            with open(tmp, "wb") as stream:
                np.savez(stream, **arrays)
        else:
            import trimesh

            trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(str(tmp),
                                                                             file_type=suffix[1:])
    return path
