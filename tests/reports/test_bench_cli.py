"""``translucent bench``: options every benchmark shares, checked before it runs."""

from translucent.reports.bench import prt as bench_prt
from translucent.reports.cli import main


def test_a_json_path_that_is_a_folder_is_refused_before_the_benchmark_runs(tmp_path, capsys,
                                                                           monkeypatch):
    ran = []
    monkeypatch.setattr(bench_prt, "run", lambda args: ran.append(args) or 0)
    assert main(["bench", "prt", "--json", str(tmp_path)]) == 2
    assert ran == []
    assert "--json" in capsys.readouterr().err
