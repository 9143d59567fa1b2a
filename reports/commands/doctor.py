"""Print versions, the Mitsuba variant, the libLLVM path, GPU use and the cache folder.

Python, Mitsuba and Dr.Jit versions, the variant chosen, the libLLVM path, whether a GPU
is usable (by Mitsuba, and by numba.cuda for the splatting backend ``cuda``), and the cache
folder.
"""

from __future__ import annotations


def add_arguments(parser):
    """No options."""


def run(args) -> int:
    """Print one ``key: value`` line per fact."""
    from ...backend import backend_facts
    from ...cache import cache_dir
    from ...fast.splatting_cuda import available

    facts = backend_facts()
    facts["numba.cuda"] = "usable" if available() else "not usable"
    facts["cache"] = str(cache_dir())
    width = max(len(key) for key in facts)
    for key, value in facts.items():
        print(f"{key:<{width}}  {value}")
    return 0
