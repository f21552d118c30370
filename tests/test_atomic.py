"""Atomic writes (bayeshopf._atomic): a file appears whole or not at all."""

from __future__ import annotations

import os

import pytest

from bayeshopf._atomic import replacing


def _leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


def test_replacing_moves_the_finished_file_into_place(tmp_path) -> None:
    path = tmp_path / "new" / "summary.json"          # a missing parent folder is made
    with replacing(path) as tmp:
        assert tmp.parent == path.parent and not tmp.exists() and not path.exists()
        tmp.write_text("whole")
        assert not path.exists()                      # nothing visible until the block ends
    assert path.read_text() == "whole"
    assert _leftovers(path.parent) == []
    umask = os.umask(0o022)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask   # not tempfile's 0o600


def test_replacing_keeps_the_old_file_when_the_writer_fails(tmp_path) -> None:
    path = tmp_path / "posterior.nc"
    path.write_text("old")
    with pytest.raises(RuntimeError, match="interrupted"), replacing(path) as tmp:
        tmp.write_text("half")
        raise RuntimeError("interrupted")
    assert path.read_text() == "old"
    assert _leftovers(tmp_path) == []


def test_replacing_survives_a_writer_that_wrote_nothing(tmp_path) -> None:
    path = tmp_path / "figure.png"
    with pytest.raises(KeyboardInterrupt), replacing(path):
        raise KeyboardInterrupt
    assert not path.exists() and _leftovers(tmp_path) == []
