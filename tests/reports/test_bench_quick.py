"""Every benchmark runs: ``translucent bench NAME --quick`` through the installed script.

The quick run takes the same code paths as the full one at tiny sizes and writes the same
JSON; each is checked for exit 0, the JSON's keys and a finite figure in each row
(:data:`smoke.BENCHMARKS`). The benchmarks that render references are here; the others
are in ``test_bench_quick_methods.py``.
"""

from pathlib import Path

import pytest
from smoke import (
    BENCHMARKS,
    QUICK_ELSEWHERE,
    QUICK_OTHERS,
    QUICK_RENDERING,
    check_quick_bench,
    listed,
)


def test_every_benchmark_the_help_lists_has_a_quick_check():
    assert sorted(listed("bench")) == sorted(BENCHMARKS)
    assert sorted(QUICK_RENDERING + QUICK_OTHERS + tuple(QUICK_ELSEWHERE)) == sorted(BENCHMARKS)
    for name, test_file in QUICK_ELSEWHERE.items():
        assert f'check_quick_bench("{name}"' in (Path(__file__).parent / test_file).read_text()


def test_every_quick_value_is_an_option_of_its_benchmark():
    from translucent.reports.bench import prt
    from translucent.reports.cli import _build_parser

    parser = _build_parser("bench")
    benches = parser._subparsers._group_actions[0].choices["bench"]
    for name, command in benches._subparsers._group_actions[0].choices.items():
        dests = {action.dest for action in command._actions}
        quick = command.get_default("bench_quick")
        assert quick is not None, f"bench {name} has no QUICK_ARGUMENTS"
        assert set(quick) <= dests, f"bench {name}: {sorted(set(quick) - dests)}"
    assert prt.QUICK_ARGUMENTS["samples"] == "256"


def test_an_option_the_user_gives_wins_over_the_quick_value(monkeypatch, capsys, tmp_path):
    import argparse

    from translucent.reports.bench import prt
    from translucent.reports.cli import main

    seen = []
    monkeypatch.setattr(prt, "run", lambda args: seen.append(argparse.Namespace(
        **vars(args))) or 0)
    assert main(["bench", "prt", "--quick", "--frames", "5", "--json",
                 str(tmp_path / "p.json")]) == 0
    assert seen[0].frames == 5 and seen[0].vertices == prt.QUICK_ARGUMENTS["vertices"]
    assert "quick run of bench prt" in capsys.readouterr().out


@pytest.mark.parametrize("name", QUICK_RENDERING)
def test_quick_bench_runs_through_the_console_script(name, tmp_path):
    check_quick_bench(name, tmp_path)
