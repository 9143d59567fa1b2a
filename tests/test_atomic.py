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


# ---------------------------------------------------------------------- a full disk


def _no_space(*args, **kwargs):
    import errno

    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_while_writing_is_an_output_error_and_leaves_nothing(tmp_path):
    from translucent.atomic import OutputError, atomic_path

    target = tmp_path / "out.json"
    with pytest.raises(OutputError, match="out.json.*could not write it .No space left"):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"half")
            _no_space()
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("words", ["No space left on device.", "Unknown failure."])
def test_a_writers_own_error_about_the_file_is_an_output_error(tmp_path, words):
    # OpenEXR says what failed in a RuntimeError that names the file it wrote
    from translucent.atomic import OutputError, atomic_path

    target = tmp_path / "image.exr"
    with pytest.raises(OutputError) as raised:
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError(f'Failed to write pixel data to image file "{tmp}". {words}')
    assert str(target) in str(raised.value) and ".part" not in str(raised.value)
    assert not any(tmp_path.iterdir())


def test_an_error_that_is_not_the_outputs_is_raised_as_it_is(tmp_path):
    from translucent.atomic import atomic_path

    with pytest.raises(RuntimeError, match="a bug"), atomic_path(tmp_path / "x.txt"):
        raise RuntimeError("a bug")
    with pytest.raises(FileNotFoundError), atomic_path(tmp_path / "x.txt"):
        open(tmp_path / "missing input")  # noqa: SIM115
    assert not any(tmp_path.iterdir())


def test_a_failed_output_folder_leaves_no_folder_made_for_it(tmp_path, monkeypatch):
    from pathlib import Path

    from translucent.atomic import OutputError, atomic_write_text, output_folder

    (tmp_path / "kept").mkdir()
    (tmp_path / "kept" / "old.txt").write_text("keep")
    for folder in (tmp_path / "new" / "deeper", tmp_path / "kept" / "new"):
        with pytest.raises(OutputError, match="--out = .*could not write it .*No space left"):
            with output_folder(folder, field="--out", create=True):
                # as Mitsuba says it, naming no file
                raise RuntimeError("Error while writing mesh: No space left on device")
        with monkeypatch.context() as patch, pytest.raises(OutputError, match="No space left"):
            patch.setattr(Path, "write_bytes", _no_space)
            with output_folder(folder, field="--out"):
                atomic_write_text(folder / "a.txt", "never written")
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == [
        "kept", "kept/old.txt"]


def test_a_full_file_system_is_named_where_the_writer_says_nothing(tmp_path, monkeypatch):
    import os

    from translucent.atomic import OutputError, atomic_path

    class Full:
        f_bavail = 0

    monkeypatch.setattr(os, "statvfs", lambda path: Full())
    with pytest.raises(OutputError, match="No space left on device"):
        with atomic_path(tmp_path / "image.exr"):
            raise RuntimeError("Failed to write pixel data")


# ---------------------------------------------------------------------- long names


def _longest_name(tail: str) -> str:
    """A name of exactly 255 bytes (the longest most file systems take) ending in ``tail``."""
    return "\u00e9" * ((255 - len(tail.encode())) // 2) + "n" * ((255 - len(tail.encode())) % 2) \
        + tail


def test_a_name_of_the_longest_length_is_written(tmp_path):
    from translucent.atomic import atomic_write_text

    for name in (_longest_name(".exr"), "n" * 251 + ".exr", "n" * 255, "n" * 200 + "." + "x" * 54):
        assert len(name.encode()) == 255
        atomic_write_text(tmp_path / name, "written")
        assert (tmp_path / name).read_text() == "written"
    assert len(list(tmp_path.iterdir())) == 4


def test_temporary_names_fit_and_are_the_suites_own_whatever_the_target(tmp_path):
    from translucent.atomic import atomic_path
    from translucent.staging import staging_folder
    from translucent.temporaries import ORPHAN_NAME

    seen = []
    for name in (_longest_name(".exr"), "n" * 255, "short.exr", "a." + "x" * 253):
        with atomic_path(tmp_path / name) as tmp:
            seen.append(tmp.name)
        with staging_folder(tmp_path / name, field="--out") as staging:
            seen.append(staging.name)
    assert all(len(name.encode()) <= 255 and ORPHAN_NAME.match(name) for name in seen), seen


# ---------------------------------------------------------------------- staging folders


def test_a_staging_folder_is_kept_while_its_process_lives_and_removed_after(tmp_path):
    import os
    import time

    from translucent.staging import staging_folder
    from translucent.temporaries import ORPHAN_AGE_SECONDS, sweep_orphans

    with staging_folder(tmp_path / "report", field="--out") as staging:
        (staging / "index.html").write_text("being written")
        old = time.time() - 2 * ORPHAN_AGE_SECONDS  # a long run: its folder looks old
        os.utime(staging, (old, old))
        assert sweep_orphans(tmp_path, older_than=0) == []
        assert staging.is_dir()
    assert not any(tmp_path.iterdir())


def test_a_killed_runs_staging_folder_is_swept_at_once(tmp_path):
    import os
    import select
    import signal

    from translucent.staging import staging_folder
    from translucent.temporaries import sweep_orphans

    ready_read, ready_write = os.pipe()
    child = os.fork()
    if child == 0:  # the run that is killed: it makes its staging folder and waits
        try:
            with staging_folder(tmp_path / "report", field="--out") as staging:
                (staging / "index.html").write_text("half")
                os.write(ready_write, b"1")
                signal.pause()
        finally:
            os._exit(0)
    try:
        assert select.select([ready_read], [], [], 60)[0], "the run never made its folder"
        assert os.read(ready_read, 1) == b"1"
        (staging,) = tmp_path.iterdir()
        assert sweep_orphans(tmp_path) == [] and staging.is_dir()  # alive: kept
    finally:
        os.kill(child, signal.SIGKILL)
        os.waitpid(child, 0)
        os.close(ready_read)
        os.close(ready_write)
    assert sweep_orphans(tmp_path) == [staging]  # young, but its process is gone
    assert not any(tmp_path.iterdir())


def test_replacing_a_folder_keeps_the_old_one_until_the_new_one_is_in_place(tmp_path,
                                                                             monkeypatch):
    import os

    from translucent.atomic import OutputError
    from translucent.staging import replace_folder

    target = tmp_path / "report"
    target.mkdir()
    (target / "index.html").write_text("old")
    staging = tmp_path / ".report.abcd1234.part"
    staging.mkdir()
    (staging / "index.html").write_text("new")
    real_rename = os.rename

    def failing(source, destination):
        if str(source) == str(staging):
            _no_space()
        real_rename(source, destination)

    monkeypatch.setattr(os, "rename", failing)
    with pytest.raises(OutputError, match="report.*No space left"):
        replace_folder(staging, target)
    assert (target / "index.html").read_text() == "old" and staging.is_dir()
    monkeypatch.setattr(os, "rename", real_rename)
    replace_folder(staging, target)
    assert (target / "index.html").read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]
