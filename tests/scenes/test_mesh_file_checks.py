"""Mesh files that lie: header counts the file does not hold, coordinates float32 cannot
hold, and names that are no file (a FIFO), each refused naming the file and what is wrong."""

import contextlib
import os
import threading

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.scenes import Mesh, load_scene
from translucent.scenes.meshes import load_mesh

#: A PLY header before its element lines (``{vertices}``, ``{faces}``: the counts declared).
PLY_HEADER = ("ply\nformat ascii 1.0\ncomment made by hand\nelement vertex {vertices}\n"
              "property float x\nproperty float y\nproperty float z\nelement face {faces}\n"
              "property list uchar int vertex_indices\nend_header\n")

#: Three vertices and two faces, as element lines.
PLY_BODY = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n"


def _ply(path, vertices=3, faces=2, body=PLY_BODY, newline="\n"):
    text = PLY_HEADER.format(vertices=vertices, faces=faces) + body
    path.write_bytes(text.replace("\n", newline).encode("ascii"))
    return path


@contextlib.contextmanager
def _let_go_after(fifo, seconds=2.0):
    """Yield a list that says whether anything opened ``fifo`` to read it.

    After ``seconds`` a writer opens and closes it whenever a reader holds it open, so a
    reader that waits on it sees an empty file: a regression costs seconds, not the suite.
    """
    done, opened = threading.Event(), []

    def let_go():
        if done.wait(seconds):
            return
        while not done.is_set():
            with contextlib.suppress(OSError):  # ENXIO: no reader holds it open
                os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
                opened.append(fifo)
            done.wait(0.05)

    thread = threading.Thread(target=let_go, daemon=True)
    thread.start()
    try:
        yield opened
    finally:
        done.set()
        thread.join()


# --- counts declared in a header --------------------------------------------------------------

def test_an_ascii_ply_declaring_ten_million_faces_over_two_is_refused(tmp_path):
    path = _ply(tmp_path / "big.ply", faces=10_000_000)
    with pytest.raises(InputError, match=r"big\.ply: element face = 10000000: declared in the "
                                         r"PLY header, but the file holds only 2 face lines"):
        load_mesh(path)


def test_an_ascii_ply_declaring_more_vertices_than_it_holds_is_refused(tmp_path):
    path = _ply(tmp_path / "v.ply", vertices=3000)
    with pytest.raises(InputError, match=r"v\.ply: element vertex = 3000: .* holds only 5 "
                                         "vertex lines"):
        load_mesh(path)


def test_a_ply_count_that_is_not_a_number_is_refused_naming_its_line(tmp_path):
    path = _ply(tmp_path / "word.ply", faces="many")
    with pytest.raises(InputError, match=r"word\.ply: element face \(line 8\) = 'many': a count "
                                         "must be a whole number"):
        load_mesh(path)


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_an_ascii_ply_holding_its_counts_loads(tmp_path, newline):
    path = _ply(tmp_path / "ok.ply", body=PLY_BODY + "\n\n", newline=newline)
    mesh = load_mesh(path)
    assert (len(mesh.vertices), len(mesh.faces)) == (3, 2)


def test_a_binary_ply_is_left_to_its_reader(tmp_path):
    import trimesh

    path = tmp_path / "binary.ply"
    trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False).export(path)
    assert len(load_mesh(path).faces) == 1


@pytest.mark.parametrize("counts, words", [
    ("3 10000000 0", r"face count \(line 3\) = 10000000: declared in the OFF header, but the "
                     "file holds only 2 face lines"),
    ("30 2 0", r"vertex count \(line 3\) = 30: .* holds only 5 vertex lines"),
    ("3 -2 0", r"face count \(line 3\) = '-2': a count must be a whole number >= 0"),
])
def test_an_off_declaring_what_it_does_not_hold_is_refused(tmp_path, counts, words):
    path = tmp_path / "m.off"
    path.write_text(f"OFF\n# a comment\n{counts}\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n")
    with pytest.raises(InputError, match=r"m\.off: " + words):
        load_mesh(path)


def test_an_off_holding_its_counts_loads_with_comments_and_counts_on_its_first_line(tmp_path):
    path = tmp_path / "ok.off"
    path.write_text("OFF 3 2 0\n# vertices\n0 0 0\n1 0 0 # one\n\n0 1 0\n3 0 1 2\n3 0 2 1\n")
    assert len(load_mesh(path).faces) == 2


# --- coordinates beyond float32 ---------------------------------------------------------------

def test_an_obj_coordinate_beyond_float32_is_refused_naming_its_line(tmp_path):
    path = tmp_path / "huge.obj"
    path.write_text("# far\nv 0 0 0\nv 1 0 0\nv 0 1e39 0\nf 1 2 3\n")
    with pytest.raises(InputError, match=r"huge\.obj: line 4 = 1e\+39: a coordinate beyond "
                                         r"float32's range"):
        load_mesh(path)


def test_an_obj_coordinate_within_float32_loads(tmp_path):
    path = tmp_path / "large.obj"
    path.write_text("v 0 0 0\nv 1e38 0 0\nv 0 1e38 0\nf 1 2 3\n")
    assert load_mesh(path).vertices.max() == 1e38


def test_a_mesh_beyond_float32_is_refused_by_vertex(tmp_path):
    with pytest.raises(InputError, match=r"vertices\[1\] = .*1 vertices are beyond float32"):
        Mesh(np.array([[0, 0, 0], [0, 0, -1e39], [0, 1, 0]]), np.array([[0, 1, 2]]))
    path = tmp_path / "far.npz"
    np.savez(path, vertices=np.array([[0, 0, 0], [1, 0, 0], [0, 4e38, 0]]),
             faces=np.array([[0, 1, 2]]))
    with pytest.raises(InputError, match=r"far\.npz: vertices\[2\] = .*beyond float32"):
        load_mesh(path)


# --- names that are no file -------------------------------------------------------------------

@pytest.mark.parametrize("name, reader", [("m.obj", load_mesh), ("s.toml", load_scene)])
def test_a_fifo_is_refused_before_it_is_opened(tmp_path, name, reader):
    fifo = tmp_path / name
    os.mkfifo(fifo)
    with _let_go_after(fifo) as opened, pytest.raises(
            InputError, match=rf"{name.replace('.', '[.]')}.*is a FIFO"):
        reader(fifo)
    assert not opened
