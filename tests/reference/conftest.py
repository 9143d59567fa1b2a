"""The helper modules this folder's tests share (``bssrdf_checks.py``, ...) are imported by name.

The tests run with ``--import-mode=importlib``, which puts no test folder on ``sys.path``;
this folder is put there for them.
"""

import sys
from pathlib import Path

if str(Path(__file__).parent) not in sys.path:
    sys.path.insert(0, str(Path(__file__).parent))
