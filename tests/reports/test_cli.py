"""The ``translucent`` entry point: exit codes and ``TRANSLUCENT_OPTIONS``."""

from translucent.reports.bench import prt as bench_prt
from translucent.reports.cli import main


def test_options_from_the_environment_reach_the_command(monkeypatch, capsys):
    monkeypatch.setenv("TRANSLUCENT_OPTIONS", "--show sphere")
    assert main(["scenes"]) == 0
    assert "object sphere:" in capsys.readouterr().out


def test_options_from_the_environment_reach_a_nested_command(monkeypatch, capsys):
    def never():
        raise AssertionError("measured with the environment's options ignored")

    monkeypatch.setattr(bench_prt, "memory_bandwidth", never)
    monkeypatch.setenv("TRANSLUCENT_OPTIONS", "--frames 0")
    assert main(["bench", "prt"]) == 2
    assert "--frames = 0: must be an integer >= 1" in capsys.readouterr().err


def test_the_command_line_overrides_the_environment(monkeypatch, capsys):
    monkeypatch.setenv("TRANSLUCENT_OPTIONS", "--show no_such_scene")
    assert main(["scenes", "--show", "sphere"]) == 0
    assert "object sphere:" in capsys.readouterr().out


def test_options_a_command_does_not_take_are_named_as_from_the_environment(monkeypatch,
                                                                          capsys):
    monkeypatch.setenv("TRANSLUCENT_OPTIONS", "--no-such-option")
    assert main(["scenes"]) == 2
    assert "TRANSLUCENT_OPTIONS" in capsys.readouterr().err


def test_unbalanced_quotes_in_the_environment_are_bad_usage(monkeypatch, capsys):
    monkeypatch.setenv("TRANSLUCENT_OPTIONS", '--show "sphere')
    assert main(["scenes"]) == 2
    assert "TRANSLUCENT_OPTIONS" in capsys.readouterr().err
