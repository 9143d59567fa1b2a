"""The ``translucent`` entry point: exit codes and ``TRANSLUCENT_OPTIONS``."""

import pytest
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


def test_options_a_command_does_not_take_are_left_out_with_a_note(monkeypatch, capsys):
    # one variable serves every command: an option this one lacks never breaks it
    monkeypatch.setenv("TRANSLUCENT_OPTIONS", "--no-such-option 3 --show sphere")
    assert main(["scenes"]) == 0
    captured = capsys.readouterr()
    assert "object sphere:" in captured.out
    assert "TRANSLUCENT_OPTIONS '--no-such-option 3' left out" in captured.err


def test_an_accepted_option_keeps_its_values_even_a_dash(monkeypatch):
    from translucent.reports.cli import _accepted_options, _build_parser, _command_end

    parser = _build_parser(every=True)
    _, references = _command_end(parser, ["references", "list"])
    kept, ignored = _accepted_options(references, ["--json", "-", "--bogus=1", "--budget",
                                                   "-1", "--no-progress"])
    assert ignored == ["--bogus=1"]
    assert kept == ["--json", "-", "--budget", "-1", "--no-progress"]


def test_an_invalid_value_of_an_accepted_option_is_still_bad_usage(monkeypatch, capsys):
    monkeypatch.setenv("TRANSLUCENT_OPTIONS", "--spp many")
    assert main(["render", "glossy"]) == 2
    err = capsys.readouterr().err
    assert "invalid int value: 'many'" in err and "TRANSLUCENT_OPTIONS" in err


def test_unbalanced_quotes_in_the_environment_are_bad_usage(monkeypatch, capsys):
    monkeypatch.setenv("TRANSLUCENT_OPTIONS", '--show "sphere')
    assert main(["scenes"]) == 2
    assert "TRANSLUCENT_OPTIONS" in capsys.readouterr().err


# ---------------------------------------------------------------- signals, variants


def _translucent(*arguments, env=None, **options):
    import os
    import subprocess
    import sys

    environment = {**os.environ, **(env or {})}
    return subprocess.Popen([sys.executable, "-m", "translucent.reports.cli", *arguments],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=environment, **options)


@pytest.mark.parametrize("signal_name, code, word", [
    ("SIGINT", 130, "interrupted"),
    pytest.param("SIGTERM", 143, "terminated", marks=pytest.mark.slow)])  # same path, 6 s
def test_a_signal_ends_a_render_with_one_line_and_nothing_left(tmp_path, signal_name, code,
                                                               word):
    import signal
    import time

    out = tmp_path / "new" / "glossy.exr"
    process = _translucent("render", "glossy", "--spp", "256", "--passes", "400",
                           "--no-cache", "--no-progress", "-o", str(out))
    time.sleep(6.0)  # into the render
    process.send_signal(getattr(signal, signal_name))
    _, err = process.communicate(timeout=60)
    assert process.returncode == code, err
    assert err.strip().endswith(f"translucent render: {word}"), err
    assert "Traceback" not in err
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("signal_error, code, word", [(KeyboardInterrupt, 130, "interrupted"),
                                                       ("Terminated", 143, "terminated")])
def test_a_signal_wrapped_by_a_renderer_plugin_still_ends_with_one_line(monkeypatch, capsys,
                                                                        signal_error, code,
                                                                        word):
    # A signal that lands in a Python BSDF reaches the caller as Dr.Jit's RuntimeError
    # raised from the KeyboardInterrupt (or Terminated).
    from translucent.reports import cli
    from translucent.reports.commands import scenes

    cause = cli.Terminated() if signal_error == "Terminated" else signal_error()

    def run(args):
        try:
            raise cause
        except BaseException as error:
            raise RuntimeError("drjit.custom(...): error while performing a custom "
                               "differentiable operation. (see above).") from error

    monkeypatch.setattr(scenes, "run", run)
    assert cli.main(["scenes"]) == code
    assert capsys.readouterr().err.strip() == f"translucent scenes: {word}"


def test_an_error_with_no_signal_behind_it_is_not_taken_for_one(monkeypatch):
    from translucent.reports import cli
    from translucent.reports.commands import scenes

    def run(args):
        raise RuntimeError("a bug")

    monkeypatch.setattr(scenes, "run", run)
    with pytest.raises(RuntimeError, match="a bug"):
        cli.main(["scenes"])


@pytest.mark.parametrize("shown", [False, True])
def test_a_bug_reaches_a_user_as_one_line_unless_the_traceback_is_asked_for(shown):
    # the console script's entry point, with the scenes command broken on purpose
    import os
    import subprocess
    import sys

    program = ("import sys; from translucent.reports import cli; "
               "from translucent.reports.commands import scenes; "
               "scenes.run = lambda args: {}['no such key']; "
               "sys.argv = ['translucent', 'scenes']; cli.entry_point()")
    environment = {key: value for key, value in os.environ.items()
                   if key != "TRANSLUCENT_TRACEBACK"}
    if shown:
        environment["TRANSLUCENT_TRACEBACK"] = "1"
    result = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True,
                            env=environment, timeout=120)
    if shown:
        assert result.returncode == 1 and "Traceback" in result.stderr
        return
    assert result.returncode == 3
    assert "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines() == [
        "translucent scenes: internal error, a bug in translucent (KeyError: 'no such key'); "
        "TRANSLUCENT_TRACEBACK=1 shows its traceback"]


def test_an_unusable_variant_is_an_input_error_and_doctor_reports_it(tmp_path):
    env = {"TRANSLUCENT_VARIANT": "cuda_ad_rgb"}
    process = _translucent("render", "glossy", "--spp", "1", "--passes", "2",
                           "-o", str(tmp_path / "v" / "x.exr"), env=env)
    _, err = process.communicate(timeout=120)
    if "usable" not in err:
        pytest.skip("this machine has a usable CUDA GPU")
    assert process.returncode == 2 and "TRANSLUCENT_VARIANT = 'cuda_ad_rgb'" in err
    assert not (tmp_path / "v").exists()
    doctor = _translucent("doctor", env=env)
    out, err = doctor.communicate(timeout=120)
    assert doctor.returncode == 1 and "UNUSABLE" in out and "Traceback" not in err


def test_doctor_reports_an_unwritable_cache(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    doctor = _translucent("doctor", env={"TRANSLUCENT_CACHE": str(blocker / "cache")})
    out, _ = doctor.communicate(timeout=120)
    assert doctor.returncode == 1 and "NOT WRITABLE" in out


def _command_paths(parser, prefix=()):
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield (*prefix, name)
                yield from _command_paths(sub, (*prefix, name))


def test_every_command_prints_its_help(capsys):
    """A '%' in a help text is a format directive to argparse: --help must never crash."""
    from translucent.reports.cli import _build_parser

    paths = list(_command_paths(_build_parser(every=True)))
    assert ("report",) in paths and ("bench", "prt") in paths and ("approx", "prt") in paths
    for path in paths:
        assert main([*path, "--help"]) == 0, path
        assert "usage: translucent" in capsys.readouterr().out, path


def test_every_command_takes_no_progress_and_it_hides_every_bar(monkeypatch, capsys):
    import argparse

    from translucent.reports.cli import _build_parser

    def leaves(parser, prefix=()):
        subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not subs:
            yield prefix, parser
        for action in subs:
            for name, sub in action.choices.items():
                yield from leaves(sub, (*prefix, name))

    found = list(leaves(_build_parser(every=True)))
    assert len(found) > 10
    for path, parser in found:
        assert "--no-progress" in parser._option_string_actions, path

    # a bar inside a step the command calls (not one of its own) is hidden too
    from translucent.reports.commands import scenes

    def run(args):
        import sys

        from tqdm.auto import tqdm

        for _ in tqdm(range(3), file=sys.stderr, mininterval=0):
            pass
        return 0

    monkeypatch.setattr(scenes, "run", run)
    assert main(["scenes", "--no-progress"]) == 0
    assert capsys.readouterr().err == ""
    assert main(["scenes"]) == 0
    assert "3/3" in capsys.readouterr().err
