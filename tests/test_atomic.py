"""Atomic writes: a figure lands complete or not at all."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402
from translucent.atomic import atomic_save_figure  # noqa: E402


def test_figure_is_written_as_png_and_closed(tmp_path):
    figure, axis = plt.subplots()
    axis.plot([0, 1], [1, 0])
    path = atomic_save_figure(tmp_path / "f.png", figure, dpi=20)
    assert path.read_bytes().startswith(b"\x89PNG")
    assert not plt.fignum_exists(figure.number)
    assert [p.name for p in tmp_path.iterdir()] == ["f.png"]


def test_a_failing_save_leaves_nothing(tmp_path, monkeypatch):
    figure, _ = plt.subplots()

    def broken(*args, **kwargs):
        raise RuntimeError("renderer failed")

    monkeypatch.setattr(figure, "savefig", broken)
    with pytest.raises(RuntimeError, match="renderer failed"):
        atomic_save_figure(tmp_path / "f.png", figure)
    assert not any(tmp_path.iterdir())
    plt.close(figure)


def test_a_folder_as_target_is_bad_input_and_nothing_is_written(tmp_path):
    from translucent.atomic import atomic_write_text
    from translucent.errors import InputError

    (tmp_path / "out").mkdir()
    with pytest.raises(InputError, match="out: path = .*is a folder"):
        atomic_write_text(tmp_path / "out", "text")
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
    assert not any((tmp_path / "out").iterdir())


def test_a_file_in_the_way_of_the_folder_is_bad_input(tmp_path):
    from translucent.atomic import atomic_write_text
    from translucent.errors import InputError

    (tmp_path / "plain").write_text("a file")
    with pytest.raises(InputError, match="cannot create the folder"):
        atomic_write_text(tmp_path / "plain" / "sub" / "x.txt", "text")
    assert (tmp_path / "plain").read_text() == "a file"


def test_an_interrupted_writes_temporaries_are_swept_by_the_next_write(tmp_path):
    import os
    import time

    from translucent.atomic import ORPHAN_AGE_SECONDS, atomic_write_text

    old = time.time() - 2 * ORPHAN_AGE_SECONDS
    orphans = [tmp_path / ".sphere.k3j_x9qa.part.exr", tmp_path / ".entry.AbCdEf12.part.pkl"]
    staging = tmp_path / ".report.zz99yy88.part"  # a report killed while it was written
    staging.mkdir()
    (staging / "index.html").write_text("half")
    for path in orphans:
        path.write_text("half-written")
    fresh = tmp_path / ".other.q1w2e3r4.part.exr"  # a write under way in another process
    fresh.write_text("being written")
    unrelated = [tmp_path / "sphere.exr", tmp_path / ".hidden_notes.part"]
    for path in unrelated:
        path.write_text("keep")
    for path in orphans + [staging]:
        os.utime(path, (old, old))
    os.utime(unrelated[1], (old, old))
    atomic_write_text(tmp_path / "result.json", "{}")
    assert not any(p.exists() for p in orphans) and not staging.exists()
    assert fresh.exists() and all(p.exists() for p in unrelated)
    assert (tmp_path / "result.json").read_text() == "{}"
