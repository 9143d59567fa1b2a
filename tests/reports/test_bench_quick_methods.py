"""Every benchmark runs, part two: the methods' own benchmarks, ``--quick``.

See ``test_bench_quick.py``: the same check, for the benchmarks that render no reference.
"""

import pytest
from smoke import QUICK_OTHERS, check_quick_bench


@pytest.mark.parametrize("name", QUICK_OTHERS)
def test_quick_bench_runs_through_the_console_script(name, tmp_path):
    check_quick_bench(name, tmp_path)
