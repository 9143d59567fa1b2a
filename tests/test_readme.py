"""README.md's two commands: each sets itself up on a fresh machine, and CI runs the test one."""

import re
import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _two_commands() -> list[str]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Two commands", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```sh\n(.*?)```", section, re.S).group(1)
    return [line.split("#", 1)[0].strip() for line in block.splitlines() if line.strip()]


def test_there_are_two_commands_the_main_job_and_the_tests():
    report, tests = _two_commands()
    assert report.endswith("tox -e report") and tests.endswith("tox")


def test_each_command_installs_what_it_runs():
    # a fresh machine has python3 and pip, not tox: each command installs tox first
    for command in _two_commands():
        first, _, _ = command.partition("&&")
        assert shlex.split(first)[:4] == ["python3", "-m", "pip", "install"], command
        assert "tox" in first


def test_ci_runs_exactly_the_readme_test_command():
    _, tests = _two_commands()
    lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text().splitlines()
             if line.strip() and not line.lstrip().startswith("#")]
    assert lines[-1] == tests
