"""The report folder: which folders a report may replace, names of any length, a full disk.

The report's own work is stood in for (no scene, no task; a file written where the scene
images go), so that each test costs a fraction of a second: what is tested is how the
folder is built beside ``--out``, marked, and put in place.
"""

import errno
import json
import os
import time
from pathlib import Path

import pytest
from hostile import tree
from translucent.atomic import atomic_write_bytes
from translucent.reports.cli import main
from translucent.reports.report import pipeline
from translucent.reports.report.pipeline import REPORT_MARKER
from translucent.temporaries import ORPHAN_AGE_SECONDS, sweep_orphans


@pytest.fixture
def stand_in(monkeypatch, tmp_path):
    """The report with its scenes and tasks stood in for; ``calls`` holds each staging folder.

    ``during`` (a list) takes functions run while the report is being written, with the
    staging folder.
    """
    def plan(*args, **kwargs):
        return pipeline._Plan(reports=[], tasks=[], scored=[], renderers=[], excluded={},
                              reference_settings={"spp": 1, "passes": 2},
                              versions={"mitsuba": "-", "variant": "-", "drjit": "-"},
                              fingerprint="stand-in", run_cache=None)

    state = {"calls": [], "during": []}

    def run(plan, staging, timing, **options):
        state["calls"].append(staging)
        atomic_write_bytes(staging / "sphere" / "reference.png", b"\x89PNG stand-in")
        for call in state["during"]:
            call(staging)
        return []

    monkeypatch.setattr(pipeline, "_plan", plan)
    monkeypatch.setattr(pipeline, "_run", run)
    monkeypatch.chdir(tmp_path)
    return state


def _report(out) -> int:
    return main(["report", "--methods", "prt", "--out", str(out), "--serial", "--no-progress",
                 "--quiet"])


def _files(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


# ---------------------------------------------------------------------- what is replaced


def test_every_report_folder_is_marked_with_the_files_it_holds(stand_in, tmp_path):
    assert _report("r") == 0
    listed = json.loads((tmp_path / "r" / REPORT_MARKER).read_text())
    assert listed["written_by"] == "translucent report"
    assert listed["files"] == ["index.html", "metrics.json", "sphere/reference.png"]
    assert _files(tmp_path / "r") == sorted(listed["files"] + [REPORT_MARKER])


def test_a_report_folder_is_replaced_whole(stand_in, tmp_path):
    assert _report("r") == 0
    (tmp_path / "r" / "sphere" / "reference.png").write_bytes(b"an earlier report's")
    assert _report("r") == 0
    assert (tmp_path / "r" / "sphere" / "reference.png").read_bytes() == b"\x89PNG stand-in"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r"]  # nothing left beside it


@pytest.mark.parametrize("files, words", [
    # what a report writes, and a file of the user's: a metrics.json is no proof
    ({"metrics.json": "{}", "index.html": "<html>", "notes.txt": "mine"},
     ["a folder with other files in it", REPORT_MARKER]),
    # a report written before reports were marked: refused, saying how to replace it
    ({"metrics.json": "{}", "index.html": "<html>", "sphere/reference.png": "png"},
     ["remove it first"]),
    # a marker that is not the suite's
    ({REPORT_MARKER: '{"files": ["notes.txt"]}', "notes.txt": "mine"}, [REPORT_MARKER]),
])
def test_a_folder_that_is_no_report_is_never_replaced(stand_in, tmp_path, capsys, files,
                                                      words):
    for name, text in files.items():
        (tmp_path / "r" / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "r" / name).write_text(text)
    before = tree(tmp_path)
    assert _report("r") == 2
    err = capsys.readouterr().err
    assert "--out = 'r'" in err and all(word in err for word in words), err
    assert tree(tmp_path) == before and stand_in["calls"] == []  # refused before any work


def test_a_file_put_into_a_report_folder_keeps_it_from_being_replaced(stand_in, tmp_path,
                                                                      capsys):
    assert _report("r") == 0
    (tmp_path / "r" / "sphere" / "my notes.txt").write_text("mine")
    os.symlink("/etc", tmp_path / "r" / "link")
    before = tree(tmp_path)
    assert _report("r") == 2
    err = capsys.readouterr().err
    assert "--out = 'r'" in err and "holds link and 1 other file(s)" in err, err
    assert tree(tmp_path) == before


def test_an_empty_folder_takes_a_report(stand_in, tmp_path):
    (tmp_path / "r").mkdir()
    assert _report("r") == 0
    assert (tmp_path / "r" / "index.html").is_file()


# ---------------------------------------------------------------------- names, disks, kills


def test_a_report_of_the_longest_name_is_written_and_replaced(stand_in, tmp_path):
    name = "r" * 255  # its staging folder's name must fit too
    assert _report(name) == 0
    assert _report(name) == 0
    assert [p.name for p in tmp_path.iterdir()] == [name]
    assert (tmp_path / name / "index.html").is_file()


def test_a_full_disk_ends_the_report_with_one_line_and_leaves_nothing(stand_in, tmp_path,
                                                                      monkeypatch, capsys):
    real = Path.write_bytes

    def write_bytes(path, data):  # the scene's image is written, the page is not
        if path.name.startswith(".index."):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(path, data)

    monkeypatch.setattr(Path, "write_bytes", write_bytes)
    assert _report("new/r") == 2
    err = capsys.readouterr().err
    assert err.splitlines() == ["translucent report: error: --out = 'new/r': could not write "
                                "it (index.html: No space left on device)"], err
    assert stand_in["calls"] and not any(tmp_path.iterdir())


def test_the_staging_folder_is_never_swept_while_the_report_runs(stand_in, tmp_path):
    def sweep_meanwhile(staging):  # as another command writing beside it would, much later
        old = time.time() - 2 * ORPHAN_AGE_SECONDS
        os.utime(staging, (old, old))
        assert sweep_orphans(staging.parent, older_than=0) == []

    stand_in["during"].append(sweep_meanwhile)
    assert _report("r") == 0
    assert (tmp_path / "r" / "sphere" / "reference.png").is_file()
