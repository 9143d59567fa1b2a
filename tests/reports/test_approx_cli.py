"""``translucent approx``: the output path is checked before the method runs."""

import pytest
from translucent.fast import prt
from translucent.reports.cli import main


@pytest.fixture
def method_runs(monkeypatch):
    """Record whether the method was asked to render (it must not be, on a bad --out)."""
    calls = []

    def approx(scene, args):
        calls.append(scene.name)
        raise AssertionError("the method ran before the output path was checked")

    monkeypatch.setattr(prt, "approx", approx)
    return calls


@pytest.mark.parametrize("name, message", [
    ("prt.png", "must be an OpenEXR file ending in .exr"),
    ("folder.exr", "is a folder"),
])
def test_a_bad_output_is_refused_before_the_method_runs(tmp_path, capsys, method_runs, name,
                                                        message):
    (tmp_path / "folder.exr").mkdir()
    code = main(["approx", "prt", "sphere", "--no-progress", "--out", str(tmp_path / name)])
    assert code == 2
    assert message in capsys.readouterr().err
    assert method_runs == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.exr"]
