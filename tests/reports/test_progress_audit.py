"""Every step of a command that lasts more than a second shows a progress bar (slow).

A thread samples, every 50 ms, whether a progress bar is open while the command runs in
this process with standard error taken for a terminal; a span without one longer than
:data:`LONGEST_SILENCE_SECONDS` fails, naming the code that ran then. The first
:data:`STARTUP_SECONDS` (imports, building the command line) are not a step.
"""

import collections
import sys
import threading
import time
import traceback

import pytest
from translucent.reports.cli import main

LONGEST_SILENCE_SECONDS = 1.0
STARTUP_SECONDS = 2.0
SAMPLE_SECONDS = 0.05


class _Terminal:
    """Standard error that says it is a terminal, written to a file."""

    def __init__(self, handle):
        self._handle = handle

    def isatty(self):
        return True

    def __getattr__(self, name):
        return getattr(self._handle, name)


def _silences(argv, log_path):
    from tqdm import std

    main_thread = threading.current_thread()
    samples, done = [], threading.Event()

    def where():
        stack = traceback.extract_stack(sys._current_frames().get(main_thread.ident))
        ours = [f"{f.filename.rsplit('/', 2)[-1]}:{f.lineno} {f.name}" for f in stack
                if "translucent" in f.filename or "/work/" in f.filename]
        return " <- ".join(reversed(ours[-3:]))

    def sample():
        while not done.is_set():
            shown = any(not getattr(bar, "disable", False) for bar in list(std.tqdm._instances))
            samples.append((time.perf_counter(), shown, None if shown else where()))
            time.sleep(SAMPLE_SECONDS)

    sampler = threading.Thread(target=sample, daemon=True)
    with open(log_path, "w") as handle:
        original, sys.stderr = sys.stderr, _Terminal(handle)
        started = time.perf_counter()
        sampler.start()
        try:
            code = main(argv)
        finally:
            done.set()
            sampler.join()
            sys.stderr = original
    spans, current = [], []
    for moment, shown, place in samples:
        if shown or moment - started < STARTUP_SECONDS:
            if current:
                spans.append(current)
            current = []
        else:
            current.append((moment, place))
    if current:
        spans.append(current)
    silences = []
    for span in spans:
        length = span[-1][0] - span[0][0]
        if length > LONGEST_SILENCE_SECONDS:
            places = collections.Counter(place for _, place in span).most_common(2)
            silences.append(f"{length:.1f} s: {places}")
    return code, silences


@pytest.mark.slow
@pytest.mark.parametrize("argv", [
    ["approx", "radiosity", "sphere", "--out", "{tmp}/radiosity.exr"],
    ["bench", "reference", "--json", "{tmp}/reference.json"],
    ["capture", "skin1", "--photons", "1e5", "--out", "{tmp}/capture.json"],
])
def test_no_step_longer_than_a_second_goes_without_a_progress_bar(argv, tmp_path):
    argv = [part.replace("{tmp}", str(tmp_path)) for part in argv]
    code, silences = _silences(argv, tmp_path / "stderr.log")
    assert code == 0, (tmp_path / "stderr.log").read_text()[-2000:]
    assert not silences, silences
