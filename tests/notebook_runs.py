"""Running the notebooks in tests: a copy in fast mode, or the stored outputs (never rewritten)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest


@dataclass(frozen=True)
class NotebookRun:
    """What a notebook's code cells hold after a run.

    Attributes:
        code: The code cells.
        outputs: Their outputs, in order.
        text: The printed (stream) text, joined.
        n_images: How many PNG images were displayed.
        errors: The error outputs.
    """

    code: list
    outputs: list
    text: str
    n_images: int
    errors: list


def _outputs(nb) -> NotebookRun:
    code = [c for c in nb.cells if c.cell_type == "code"]
    outputs = [o for c in code for o in c.get("outputs", [])]
    return NotebookRun(
        code=code, outputs=outputs,
        text="".join(o.get("text", "") for o in outputs if o.output_type == "stream"),
        n_images=sum("image/png" in o.get("data", {}) for o in outputs),
        errors=[o for o in outputs if o.output_type == "error"],
    )


def stored(notebook: Path) -> NotebookRun:
    """The outputs kept in the repository's notebook."""
    nbformat = pytest.importorskip("nbformat")
    return _outputs(nbformat.read(notebook, as_version=4))


def execute_fast(notebook: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, *,
                 timeout: int = 1800, workdir: Path | None = None) -> NotebookRun:
    """Execute a copy of ``notebook`` with ``BAYESHOPF_FAST=1`` in a fresh kernel.

    The copy lies in ``tmp_path`` and is written back there after the run (for
    inspection after a failure); the stored notebook is never executed or
    rewritten. The kernel inherits this process's environment (set variables with
    ``monkeypatch`` before the call) and runs in ``workdir`` (default: ``tmp_path``).
    A failing cell raises ``CellExecutionError``.
    """
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    copy = tmp_path / notebook.name
    copy.write_bytes(notebook.read_bytes())
    nb = nbformat.read(copy, as_version=4)
    monkeypatch.setenv("BAYESHOPF_FAST", "1")
    monkeypatch.delenv("MPLBACKEND", raising=False)   # the notebooks select inline themselves
    client = nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3",
                                     resources={"metadata": {"path": str(workdir or tmp_path)}})
    try:
        client.execute()
    finally:
        nbformat.write(nb, copy)
    return _outputs(nb)


def built_sources(script: Path) -> list[tuple[str, str]]:
    """The cells (type, source) that a ``notebooks/_src/build_NN.py`` script writes.

    The script runs with ``nbformat.write`` caught, so nothing is written.
    """
    nbformat = pytest.importorskip("nbformat")
    written = []
    mp = pytest.MonkeyPatch()
    mp.setattr(nbformat, "write", lambda nb, path, *a, **k: written.append(nb))
    try:
        exec(compile(script.read_text(), str(script), "exec"),
             {"__file__": str(script), "__name__": "__main__"})
    finally:
        mp.undo()
    assert len(written) == 1, f"{script.name} wrote {len(written)} notebooks"
    return [(c.cell_type, c.source) for c in written[0].cells]
