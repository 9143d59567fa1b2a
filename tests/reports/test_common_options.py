"""The options every command shares: ``--no-progress``, ``--quiet`` and ``--json FILE``."""

import argparse
import json

import numpy as np
import pytest
from translucent.image import Image, write_exr
from translucent.reports.cli import _build_parser, main


def _leaf_parsers(parser, path=()):
    """Yield ``(command words, parser)`` of every command and sub-command that runs."""
    choices = next((action.choices for action in parser._actions
                    if isinstance(action, argparse._SubParsersAction)), None)
    if not choices:
        yield path, parser
        return
    for name, child in choices.items():
        yield from _leaf_parsers(child, (*path, name))


def test_every_command_takes_the_common_options():
    leaves = dict(_leaf_parsers(_build_parser(every=True)))
    # the commands the convention names, each present
    for command in ("compare", "fit", "render", "report", "doctor", "scenes", "stress",
                    "references", "capture", "capture-import"):
        assert (command,) in leaves, command
    assert any(path[0] == "approx" for path in leaves)
    assert any(path[0] == "bench" for path in leaves)
    for path, parser in leaves.items():
        for option in ("--no-progress", "--quiet", "--json"):
            assert option in parser._option_string_actions, (path, option)


def _pair(folder, scale=1.3):
    y, x = np.mgrid[0:24, 0:32] / 32
    truth = np.stack([0.2 + x, 0.3 + y, 0.5 + x * y], axis=-1).astype(np.float32)
    write_exr(folder / "ref.exr", Image(truth, (0.01 * truth) ** 2))
    write_exr(folder / "test.exr", Image(scale * truth))
    return str(folder / "ref.exr"), str(folder / "test.exr")


def test_quiet_prints_nothing_on_standard_output(tmp_path, capsys):
    reference, test = _pair(tmp_path)
    assert main(["compare", reference, test, "--no-maps", "--quiet"]) == 0
    assert main(["scenes", "--quiet"]) == 0
    assert main(["doctor", "-q"]) in (0, 1)
    assert capsys.readouterr().out == ""


def test_quiet_keeps_warnings_and_the_exit_code(tmp_path, capsys):
    y, x = np.mgrid[0:24, 0:32] / 32
    truth = np.stack([0.2 + x, 0.3 + y, 0.5 + x * y], axis=-1).astype(np.float32)
    write_exr(tmp_path / "ref.exr", Image(truth, (0.2 * truth) ** 2))  # a noisy reference
    write_exr(tmp_path / "test.exr", Image(2 * truth))
    code = main(["compare", str(tmp_path / "ref.exr"), str(tmp_path / "test.exr"),
                 "--no-maps", "--quiet", "--max", "0.01"])
    assert code == 1
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "warning: the reference is noisy" in captured.err


def test_compare_records_each_metric_with_its_noise_floor_and_verdict(tmp_path, capsys):
    reference, test = _pair(tmp_path)
    record = tmp_path / "out" / "compare.json"
    assert main(["compare", reference, test, "--no-maps", "--json", str(record),
                 "--max", "1"]) == 0
    content = json.loads(record.read_text())
    assert content["command"] == "compare" and content["exit_code"] == 0
    assert (content["width"], content["height"]) == (32, 24)
    metrics = {row["metric"]: row for row in content["metrics"]}
    assert set(metrics) >= {"relative_mse", "rmse", "psnr", "ssim", "hdr_flip", "ldr_flip",
                            "ciede2000"}
    for row in metrics.values():
        assert row["noise_floor"] is not None and row["verdict"] == "resolved", row
    # the record holds the numbers the table prints
    printed = {line.split()[0]: float(line.split()[1])
               for line in capsys.readouterr().out.splitlines()
               if line.split() and line.split()[0] in metrics}
    for name, value in printed.items():
        assert value == pytest.approx(metrics[name]["value"], rel=1e-5)
    assert metrics["hdr_flip"]["within_threshold"] is True
    assert [p.name for p in record.parent.iterdir()] == ["compare.json"]  # no temporary left


def test_json_on_standard_output_is_the_only_thing_there(tmp_path, capsys):
    assert main(["scenes", "--json", "-"]) == 0
    content = json.loads(capsys.readouterr().out)
    names = [entry["name"] for entry in content["scenes"]]
    assert "sphere" in names and "sphere_dielectric" in names
    assert main(["scenes", "--show", "sphere", "--json", "-"]) == 0
    scene = json.loads(capsys.readouterr().out)["scene"]
    assert scene["name"] == "sphere" and scene["objects"][0]["faces"] > 0


def test_a_json_file_that_cannot_be_written_is_refused_before_the_command_runs(
        tmp_path, capsys, monkeypatch):
    from translucent.reports.commands import scenes

    def never(args):
        raise AssertionError("ran before --json was checked")

    monkeypatch.setattr(scenes, "run", never)
    (tmp_path / "folder").mkdir()
    assert main(["scenes", "--json", str(tmp_path / "folder")]) == 2
    err = capsys.readouterr().err
    assert "--json" in err and "is a folder" in err


def test_bad_input_writes_no_record(tmp_path, capsys):
    record = tmp_path / "r.json"
    assert main(["compare", str(tmp_path / "missing.exr"), str(tmp_path / "nope.exr"),
                 "--json", str(record)]) == 2
    assert not record.exists()
    assert main(["scenes", "--show", "no_such_scene", "--json", str(record)]) == 2
    assert not record.exists()
    assert "error" in capsys.readouterr().err


def test_quiet_from_the_environment_applies_to_any_command(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("TRANSLUCENT_OPTIONS", "--quiet --no-progress")
    reference, test = _pair(tmp_path)
    assert main(["compare", reference, test, "--no-maps"]) == 0
    assert main(["scenes"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and "left out" not in captured.err
