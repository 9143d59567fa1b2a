"""Print versions, the Mitsuba variant, the libLLVM path, GPU use, the cache and renderers.

Python, Mitsuba and Dr.Jit versions, the variant chosen, the libLLVM path, whether a GPU
is usable (by Mitsuba, and by numba.cuda for the splatting backend ``cuda``), the cache
folder and the key that authenticates its entries, and whether each other renderer the
report can score (``--renderers``: Blender Cycles through ``bpy``) can run here. A setting
the machine cannot honour (``TRANSLUCENT_VARIANT`` naming a variant that cannot run here, a
``TRANSLUCENT_CACHE`` that cannot be written) is reported on its line and makes the exit
code 1.
"""

from __future__ import annotations


def add_arguments(parser):
    """No options."""


def _cache_state() -> tuple[str, bool]:
    """Return the cache folder and whether an entry can be written there."""
    import tempfile

    from ...cache import cache_dir

    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".doctor-"):
            pass
    except OSError as error:
        return (f"{folder} (NOT WRITABLE: {error.strerror or error}; set TRANSLUCENT_CACHE "
                "to a writable folder)"), False
    return str(folder), True


def _renderers() -> str:
    """Return each registered renderer and whether it can run here (why not, briefly)."""
    from ...errors import InputError
    from ...reference.peers.registry import renderer, renderer_names

    states = []
    for name in renderer_names():
        try:
            missing = renderer(name).available()
        except InputError as error:
            missing = error.reason
        states.append(f"{name} " + ("usable" if missing is None else
                                    f"not usable ({missing.split(';')[0]})"))
    return "; ".join(states) or "none registered"


def run(args) -> int:
    """Print one ``key: value`` line per fact; 1 when a setting cannot be honoured."""
    import sys

    from ...backend import backend_facts
    from ...errors import InputError
    from ...fast.splatting.backend_cuda import available
    from .record import record

    status = 0
    try:
        facts = backend_facts()
    except InputError as error:
        facts = {"python": sys.version.split()[0], "variant": f"UNUSABLE: {error}"}
        status = 1
    facts["numba.cuda"] = "usable" if available() else "not usable"
    facts["cache"], writable = _cache_state()
    facts["renderers"] = _renderers()
    status = max(status, 0 if writable else 1)
    width = max(len(key) for key in facts)
    for key, value in facts.items():
        print(f"{key:<{width}}  {value}")
    record(args, facts={key: str(value) for key, value in facts.items()})
    return status
