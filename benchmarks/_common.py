"""Helpers shared by the benchmark scripts (atomic writes, the rig's recordings).

Importing this module puts the repository's ``tests/`` folder on ``sys.path`` once, so
that the scripts import the test bed (``from testbed import independent_effects``) by
the same name as the tests do.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

_TESTS = str(Path(__file__).resolve().parents[1] / "tests")
if _TESTS not in sys.path:
    sys.path.insert(0, _TESTS)

#: Where runs that no document quotes go (per-label, per-setting copies); ignored by git.
RESULTS_DIR = Path(__file__).resolve().parent / "results"

#: The authors' 7 CBC recordings (never committed; ../shared beside the repository).
CBC_DIR = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data" /
           "flutter_cbc").resolve()


def atomic_write(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and ``os.replace``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.replace(tmp, path)


def rig_recordings():
    """The 7 CBC recordings from ../shared, or ``None`` (with a message) when absent."""
    from bayeshopf import datasets

    if not CBC_DIR.is_dir():
        print(f"benchmark: the recordings are not at {CBC_DIR}", file=sys.stderr)
        return None
    return datasets.flutter_cbc(CBC_DIR)


def exit_on_help(doc: str | None, argv: list[str] | None = None) -> None:
    """Print the script's docstring and exit 0 when ``-h`` or ``--help`` is an argument.

    Every script calls this first, so that ``python benchmarks/SCRIPT.py --help``
    imports the script (and with it the package names it uses at the top) and
    says how to run it, without starting a measurement.
    """
    args = sys.argv[1:] if argv is None else argv
    if "-h" in args or "--help" in args:
        print((doc or "").strip())
        raise SystemExit(0)
