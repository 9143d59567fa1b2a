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
