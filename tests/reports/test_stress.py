import json

from translucent.reports import stress
from translucent.reports.cli import main


def test_material_kernels_pass_and_write_json(tmp_path, capsys):
    out = tmp_path / "stress.json"
    assert main(["stress", "--only", "total diffuse", "--only", "Fresnel", "--json",
                 str(out)]) == 0
    results = json.loads(out.read_text())
    assert set(results) == {"total diffuse reflectance", "Fresnel transmittance"}
    assert all(r["passed"] and r["nan"] == 0 for r in results.values())


def test_a_failing_kernel_makes_the_command_exit_1(tmp_path, monkeypatch):
    @stress.stress_kernel("always nan (test)")
    def broken():
        return stress.StressResult(evaluations=1, nan=1, bound=1.0)

    try:
        assert main(["stress", "--only", "always nan", "--json", str(tmp_path / "s.json")]) == 1
    finally:
        stress._KERNELS.pop("always nan (test)")


def test_unknown_kernel_is_bad_input(tmp_path):
    assert main(["stress", "--only", "no such kernel", "--json", str(tmp_path / "s.json")]) == 2
    assert not (tmp_path / "s.json").exists()


def test_a_json_path_that_is_a_folder_is_refused_before_any_kernel_runs(tmp_path, capsys):
    ran = []

    @stress.stress_kernel("records its run (test)")
    def recorded():
        ran.append(True)
        return stress.StressResult(evaluations=1, bound=1.0)

    try:
        assert main(["stress", "--only", "records its run", "--json", str(tmp_path)]) == 2
    finally:
        stress._KERNELS.pop("records its run (test)")
    assert ran == []
    assert "--json" in capsys.readouterr().err
