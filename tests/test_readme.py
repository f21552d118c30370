"""Every code block of README.md runs, as a user without ../shared would run it.

* ```` ```python ```` blocks run in order in one namespace, in a temporary folder;
* in ```` ```bash ````/```` ```console ```` blocks every line that starts with
  ``bayeshopf`` runs (``--fast`` added to the commands that fit), in order, in one
  temporary folder: through :func:`bayeshopf.cli.main.main` but the
  :data:`SLOW_COMMANDS`, and all of them, each in its own process, with
  ``-m slow``; every other line must be one of the setup commands in :data:`EXEMPT`;
* ```` ```toml ```` blocks are rig descriptions: each is read by
  :meth:`RigDescription.from_file`;
* blocks in any other language, or none, are listings (a manifest, a CSV
  header, the package layout), not code.

The authors' rig is downloaded by ``flutter_cbc(download=True)`` and ``fit
--dataset`` from a local mirror of ``../shared/data/flutter_cbc`` into an empty
cache (tests/conftest.py ``user_without_shared``): the tests never use the
network, and skip when ../shared is absent. The fits of the Python blocks use
:meth:`CollapsedSettings.fast` unless a block passes its own settings.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).parents[1] / "README.md"

#: Lines of shell blocks that are not ``bayeshopf`` commands: the setup a user
#: runs once (creating the environment, installing, the test suite). Each is
#: exercised elsewhere (.ci/run runs the install and the tests on a clean clone).
EXEMPT = {
    'python3.11 -m venv .venv && .venv/bin/pip install -e . && .venv/bin/bayeshopf demo':
        "install and demo: .ci/run installs; `bayeshopf demo` is run below",
    'python3.11 -m venv .venv && .venv/bin/pip install -e ".[dev]" && .venv/bin/python -m pytest':
        "install and the test suite itself",
}


#: Commands that take more than a minute even with ``--fast``, or that need
#: the output of one that does: run only with ``-m slow``.
SLOW_COMMANDS = ("demo", "simulate", "discrepancy")


def blocks(lang: tuple[str, ...]) -> list[str]:
    """The README's fenced blocks in the languages ``lang``, in order."""
    text = README.read_text()
    return [m.group(2) for m in re.finditer(r"^```(\w*)\n(.*?)^```", text, re.M | re.S)
            if m.group(1) in lang]


def commands() -> list[list[str]]:
    """Every ``bayeshopf`` command of the shell blocks as an argv, in order."""
    out = []
    for block in blocks(("bash", "console", "sh", "shell")):
        for line in block.splitlines():
            line = line.strip().removeprefix("$ ")
            if not line or line.startswith("#"):
                continue
            if line.startswith("bayeshopf "):
                out.append(shlex.split(line, comments=True)[1:])
            else:
                assert line in EXEMPT, f"README shell line, not bayeshopf nor exempt: {line}"
    return out


def test_readme_has_the_blocks_this_test_runs() -> None:
    assert len(blocks(("python",))) >= 2
    argvs = commands()
    assert ["fit", "--dataset", "flutter_cbc", "--out", "rig-fit"] in argvs
    assert any(a[0] == "predict" for a in argvs) and any(a[0] == "demo" for a in argvs)
    for line in EXEMPT:   # an exemption that is no longer in the README is stale
        assert line in README.read_text(), line


def test_the_names_the_readme_uses_are_exported() -> None:
    """Every ``bh.NAME`` of the README is a public name of ``bayeshopf``."""
    import bayeshopf

    used = set(re.findall(r"\bbh\.([A-Za-z_]\w*)", README.read_text()))
    assert {"fit", "load_fit", "read_recordings", "next_measurements"} <= used
    assert used <= set(bayeshopf.__all__), sorted(used - set(bayeshopf.__all__))


def test_the_docs_code_blocks_are_the_readmes() -> None:
    """A code block of the method documents (docs/*.md, the site) is one the README runs.

    The changelog is a record, not instructions, and is left out.
    """
    readme = blocks(("python", "bash"))
    for page in sorted((README.parent / "docs").glob("*.md")):
        if page.name == "changelog.md":
            continue
        text = page.read_text()
        for m in re.finditer(r"^```(python|bash)\n(.*?)^```", text, re.M | re.S):
            assert m.group(2) in readme, f"{page.name}: a {m.group(1)} block the README lacks"


def test_toml_blocks_are_valid_rig_descriptions(tmp_path) -> None:
    from bayeshopf.data.rig import RigDescription

    for i, text in enumerate(blocks(("toml",))):
        path = tmp_path / f"rig{i}.toml"
        path.write_text(text)
        rig = RigDescription.from_file(path)
        names = {c.name for c in rig.channels}
        assert rig.planar is None or set(rig.planar) <= names


def test_python_blocks(user_without_shared, tmp_path, monkeypatch) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from bayeshopf import posterior
    from bayeshopf.inference.collapsed import CollapsedSettings

    def fast(fn):
        def wrapped(*args, settings=None, **kwargs):
            return fn(*args, settings=settings or CollapsedSettings.fast(), **kwargs)
        return wrapped

    monkeypatch.setattr(posterior, "fit_hybrid", fast(posterior.fit_hybrid))
    monkeypatch.setattr(posterior, "fit_auto", fast(posterior.fit_auto))
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__readme__"}
    for i, code in enumerate(blocks(("python",))):
        if "read_recordings(\"my_rig/\")" in code and not (tmp_path / "my_rig").exists():
            from bayeshopf.data import flutter_cbc, write_interchange

            write_interchange(flutter_cbc(download=True), tmp_path / "my_rig")
        exec(compile(code, f"README.md python block {i + 1}", "exec"), namespace)
    assert len(namespace["recordings"]) == 7               # the rig, from the mirror
    assert len(namespace["rs"]) == 3                       # the NumPy arrays' example
    assert sorted(p.name for p in (tmp_path / "fit_out" / "figures").iterdir())
    assert namespace["band"].sizes["mu"] == 2


def _run_commands(tmp_path, monkeypatch, capsys, slow: bool) -> list[str]:
    """Run the README's commands in order in ``tmp_path``.

    ``slow=False``: in this process through ``main(argv)``, leaving out
    :data:`SLOW_COMMANDS` and the commands that read their output. ``slow=True``:
    every command, each in its own process as from a shell.
    """
    import matplotlib

    matplotlib.use("Agg")
    from bayeshopf.cli.main import main

    monkeypatch.chdir(tmp_path)
    skipped_outputs: set[str] = set()
    ran = []
    for argv in commands():
        outputs = [argv[i + 1] for i, a in enumerate(argv[:-1]) if a in ("--out", "--to")]
        if not slow and (argv[0] in SLOW_COMMANDS or skipped_outputs & set(argv)):
            skipped_outputs |= set(outputs)
            continue
        if argv[0] in ("fit", "demo") and "--fast" not in argv:
            argv = argv + ["--fast"]
        if slow:
            r = subprocess.run([sys.executable, "-m", "bayeshopf.cli.main", *argv],
                               cwd=tmp_path, capture_output=True, text=True, timeout=1200,
                               env={**os.environ, "MPLBACKEND": "Agg"})
            code, out, err = r.returncode, r.stdout, r.stderr
        else:
            code = main(argv)
            out, err = capsys.readouterr()
        assert code == 0, f"bayeshopf {' '.join(argv)}: exit {code}\n{err}"
        assert out.strip(), f"bayeshopf {' '.join(argv)} printed nothing"
        for o in outputs:
            assert (tmp_path / o).is_dir(), f"bayeshopf {' '.join(argv)}: no {o}/"
        ran.append(argv[0])
    return ran


def test_commands(user_without_shared, tmp_path, monkeypatch, capsys) -> None:
    """The README's commands but the slow ones (``-m slow`` runs them all)."""
    ran = _run_commands(tmp_path, monkeypatch, capsys, slow=False)
    assert "fit" in ran and "predict" in ran


@pytest.mark.slow
def test_all_commands(user_without_shared, tmp_path, monkeypatch, capsys) -> None:
    ran = _run_commands(tmp_path, monkeypatch, capsys, slow=True)
    assert set(SLOW_COMMANDS) <= set(ran)


@pytest.mark.slow
def test_the_python_block_runs_as_shown_in_a_fresh_process(user_without_shared, tmp_path):
    """The README's first Python block, unchanged, in a new interpreter beside a busy core.

    ``bh.fit`` makes JAX's CPU settings itself; without them a fit beside another
    busy process could stall for minutes in XLA's compiler. A second process
    keeps one core busy meanwhile, as on a user's laptop.
    """
    import subprocess
    import sys

    from bayeshopf.data import flutter_cbc, write_interchange

    code = next(b for b in blocks(("python",)) if "import bayeshopf as bh" in b)
    write_interchange(flutter_cbc(download=True), tmp_path / "my_rig")
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                              text=True, timeout=600)
    finally:
        busy.kill()
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "fit_out" / "summary.json").is_file()
