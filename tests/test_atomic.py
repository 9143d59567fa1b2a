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
