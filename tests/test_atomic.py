"""Atomic writes (bayeshopf._atomic): a file appears whole or not at all."""

from __future__ import annotations

import os

import pytest

from bayeshopf._atomic import move_into, new_folder, replacing, vacant_folder
from bayeshopf.errors import OutputError


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


def _tree(folder):
    return {str(p.relative_to(folder)): p.read_text() for p in folder.rglob("*") if p.is_file()}


def test_move_into_renames_the_stage_to_a_missing_folder(tmp_path) -> None:
    stage, out = tmp_path / ".stage", tmp_path / "fit"
    (stage / "figures").mkdir(parents=True)
    (stage / "summary.json").write_text("new")
    (stage / "figures" / "a.png").write_text("png")
    moved = move_into(stage, out)
    assert not stage.exists()
    assert _tree(out) == {"summary.json": "new", "figures/a.png": "png"}
    assert sorted(moved) == sorted([out / "summary.json", out / "figures" / "a.png"])


def test_move_into_replaces_files_and_keeps_the_others(tmp_path) -> None:
    stage, out = tmp_path / ".stage", tmp_path / "fit"
    (stage / "figures").mkdir(parents=True)
    out.mkdir()
    (out / "summary.json").write_text("old")
    (out / "notes.txt").write_text("mine")
    (stage / "summary.json").write_text("new")
    (stage / "figures" / "a.png").write_text("png")
    move_into(stage, out)
    assert _tree(out) == {"summary.json": "new", "notes.txt": "mine", "figures/a.png": "png"}
    assert _tree(stage) == {}


def test_move_into_moves_only_the_files_named(tmp_path) -> None:
    stage, out = tmp_path / ".stage", tmp_path / "figures"
    stage.mkdir()
    out.mkdir()
    for name in ("a.png", "b.png", "scratch.tmp"):
        (stage / name).write_text(name)
    moved = move_into(stage, out, [stage / "b.png", stage / "a.png"])
    assert moved == [out / "b.png", out / "a.png"]
    assert _tree(out) == {"a.png": "a.png", "b.png": "b.png"}
    assert _tree(stage) == {"scratch.tmp": "scratch.tmp"}


def test_new_folder_replaces_the_whole_folder(tmp_path) -> None:
    out = tmp_path / "sim"
    out.mkdir()
    (out / "old.csv").write_text("old")
    with new_folder(out) as tmp:
        assert tmp.is_dir() and tmp.parent == tmp_path and not any(tmp.iterdir())
        (tmp / "new.csv").write_text("new")
        assert _tree(out) == {"old.csv": "old"}        # nothing visible until the block ends
    assert _tree(out) == {"new.csv": "new"}
    assert [p.name for p in tmp_path.iterdir()] == ["sim"]


def test_new_folder_keeps_the_old_folder_when_the_writer_fails(tmp_path) -> None:
    out = tmp_path / "deep" / "sim"                    # a missing parent folder is made
    with pytest.raises(RuntimeError, match="interrupted"), new_folder(out) as tmp:
        (tmp / "half.csv").write_text("half")
        raise RuntimeError("interrupted")
    assert not out.exists() and list((tmp_path / "deep").iterdir()) == []


def test_vacant_folder_refuses_a_file_and_a_full_folder(tmp_path) -> None:
    assert vacant_folder(str(tmp_path / "new"), False, "pass overwrite=True") == tmp_path / "new"
    (tmp_path / "empty").mkdir()
    assert vacant_folder(tmp_path / "empty", False, "x") == tmp_path / "empty"
    (tmp_path / "file").write_text("")
    with pytest.raises(OutputError, match="file: a folder to write into expected; found a file"):
        vacant_folder(tmp_path / "file", True, "x")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "a.csv").write_text("")
    with pytest.raises(OutputError, match=r"found a non-empty folder \(pass overwrite=True to "
                                          r"replace it\)"):
        vacant_folder(tmp_path / "full", False, "pass overwrite=True")
    assert vacant_folder(tmp_path / "full", True, "x") == tmp_path / "full"
