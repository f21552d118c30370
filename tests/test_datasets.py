from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pooch
import pytest

import bayeshopf
from bayeshopf.data import datasets
from bayeshopf.data.datasets import FLUTTER_CBC_ENV, FLUTTER_CBC_SHA256, flutter_cbc
from bayeshopf.errors import DataError

CBC_DIR = (Path(__file__).parents[1] / ".." / "shared" / "data" / "flutter_cbc").resolve()
needs_cbc = pytest.mark.skipif(
    not CBC_DIR.is_dir(), reason=f"flutter CBC recordings not found at {CBC_DIR}"
)


@pytest.fixture(autouse=True)
def no_network(monkeypatch: pytest.MonkeyPatch) -> None:
    for var in (FLUTTER_CBC_ENV, datasets.FLUTTER_CBC_URL_ENV, datasets.DATA_DIR_ENV):
        monkeypatch.delenv(var, raising=False)

    def refuse(*args: object, **kwargs: object) -> str:
        raise AssertionError("tests must not download")

    monkeypatch.setattr(pooch, "retrieve", refuse)


def test_hashes_match_shared_sums() -> None:
    sums = CBC_DIR / "SHA256SUMS"
    if not sums.is_file():
        pytest.skip(f"{sums} not found")
    pinned = dict(reversed(line.split()) for line in sums.read_text().splitlines() if line.strip())
    assert pinned == FLUTTER_CBC_SHA256


@needs_cbc
def test_flutter_cbc_from_path_and_env(monkeypatch: pytest.MonkeyPatch) -> None:
    rs = flutter_cbc(CBC_DIR)
    assert len(rs) == 7 and rs.planar == ("h", "alpha")
    np.testing.assert_allclose(rs.mus, [14.9, 15.6, 16.5, 17.3, 14.9, 15.7, 16.5])
    monkeypatch.setenv(FLUTTER_CBC_ENV, str(CBC_DIR))
    assert flutter_cbc().names == rs.names


def test_no_source_explains_how(monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(DataError) as err:
        flutter_cbc()
    msg = str(err.value)
    assert "\n" not in msg
    for hint in ("path=", FLUTTER_CBC_ENV, "download=True"):
        assert hint in msg


def test_missing_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(DataError, match="nope: flutter_cbc data folder"):
        flutter_cbc(tmp_path / "nope")
    monkeypatch.setenv(FLUTTER_CBC_ENV, str(tmp_path / "gone"))
    with pytest.raises(DataError, match=f"gone: .*from \\${FLUTTER_CBC_ENV}"):
        flutter_cbc(download=True)  # the environment variable wins over download


@needs_cbc
def test_missing_file_and_hash_mismatch(tmp_path: Path) -> None:
    names = list(FLUTTER_CBC_SHA256)
    for name in names[:-1]:
        (tmp_path / name).symlink_to(CBC_DIR / name)
    with pytest.raises(DataError, match=f"{names[-1]}: expected in the flutter_cbc folder"):
        flutter_cbc(tmp_path)
    bad = bytearray((CBC_DIR / names[-1]).read_bytes())
    bad[-1] ^= 0xFF
    (tmp_path / names[-1]).write_bytes(bytes(bad))
    found = hashlib.sha256(bytes(bad)).hexdigest()[:12]
    expected = FLUTTER_CBC_SHA256[names[-1]][:12]
    with pytest.raises(DataError) as err:
        flutter_cbc(tmp_path)
    msg = str(err.value)
    assert msg.startswith(names[-1]) and expected in msg and found in msg and "\n" not in msg


@needs_cbc
def test_download_uses_pinned_hashes(monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []

    def fake_retrieve(url: str, known_hash: str, fname: str, path: Path, **kw: object) -> str:
        calls.append((url, known_hash, fname, Path(path)))
        return str(CBC_DIR / fname)

    monkeypatch.setattr(pooch, "retrieve", fake_retrieve)
    rs = flutter_cbc(download=True)
    assert len(rs) == 7
    assert len(calls) == 7
    for url, known_hash, fname, path in calls:
        assert url == f"{datasets.FLUTTER_CBC_URL}{fname}"
        assert url.startswith(
            "https://github.com/Kyounghyunlee/ML_Hopf/raw/main/src/measured_data/"
        )
        assert known_hash == f"sha256:{FLUTTER_CBC_SHA256[fname]}"
        assert path == Path(pooch.os_cache("bayeshopf")) / "flutter_cbc"


def test_download_failure_is_data_error(monkeypatch: pytest.MonkeyPatch) -> None:
    def offline(url: str, **kw: object) -> str:
        raise ConnectionError("no route to host")

    monkeypatch.setattr(pooch, "retrieve", offline)
    with pytest.raises(
        DataError, match=r"CBC_stable_v14_9\.mat: download from .* no route to host"
    ):
        flutter_cbc(download=True)


def test_download_from_a_mirror_is_hash_checked_and_reused(user_without_shared) -> None:
    url, served, data_dir = user_without_shared
    n0 = len(served)
    rs = flutter_cbc(download=True)
    assert len(rs) == 7 and rs.planar == ("h", "alpha")
    assert sorted(served[n0:]) == sorted(f"/{name}" for name in FLUTTER_CBC_SHA256)
    folder = data_dir / "flutter_cbc"
    assert sorted(p.name for p in folder.glob("*.mat")) == sorted(FLUTTER_CBC_SHA256)
    assert flutter_cbc(folder).names == rs.names          # the download is a valid local copy
    n1 = len(served)
    assert datasets.download_flutter_cbc() == folder       # already there: nothing fetched
    assert flutter_cbc(download=True).names == rs.names
    assert len(served) == n1


def test_download_to_a_folder(user_without_shared, tmp_path: Path) -> None:
    to = tmp_path / "mine"
    assert datasets.download_flutter_cbc(to) == to
    assert {p.name: datasets._sha256(p) for p in to.glob("*.mat")} == FLUTTER_CBC_SHA256


def test_corrupted_cached_file_is_fetched_again(user_without_shared) -> None:
    url, served, data_dir = user_without_shared
    name = "CBC_stable_v15_6.mat"
    (data_dir / "flutter_cbc").mkdir(parents=True)
    (data_dir / "flutter_cbc" / name).write_bytes(b"half a file")
    n0 = len(served)
    assert len(flutter_cbc(download=True)) == 7
    assert f"/{name}" in served[n0:]
    assert datasets._sha256(data_dir / "flutter_cbc" / name) == FLUTTER_CBC_SHA256[name]


def test_download_with_a_wrong_hash_is_one_line(user_without_shared,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    name = "CBC_unstable_v15_6.mat"
    monkeypatch.setitem(FLUTTER_CBC_SHA256, name, "0" * 64)
    with pytest.raises(DataError) as err:
        flutter_cbc(download=True)
    msg = str(err.value)
    assert msg.startswith(f"{name}: download from {user_without_shared[0]}{name} failed")
    assert "hash" in msg.lower() and "\n" not in msg
    assert datasets.FLUTTER_CBC_URL_ENV in msg


@pytest.mark.parametrize("notebook", ["03_wind_tunnel.ipynb", "04_missing_physics.ipynb"])
def test_notebook_loads_the_rig_without_shared(notebook: str, user_without_shared,
                                               tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """The notebooks' loading lines, run where ../shared is absent: the download."""
    import os

    import nbformat

    nb = nbformat.read(Path(__file__).parents[1] / "notebooks" / notebook, as_version=4)
    code = "\n".join(c.source for c in nb.cells if c.cell_type == "code").splitlines()
    lines = [ln.strip() for ln in code if "read_recordings(" in ln or ln.startswith("DATA = ")]
    assert len(lines) == 2 and lines[0].startswith("DATA = "), lines
    assert "download=True" in lines[1]
    monkeypatch.chdir(tmp_path)
    ns = {"os": os, "Path": Path, "bh": bayeshopf}
    served = user_without_shared[1]
    n0 = len(served)
    for line in lines:
        exec(line, ns)
    assert not Path(ns["DATA"]).is_dir()
    rs = ns.get("rs", ns.get("rig"))
    assert len(rs) == 7
    assert sorted(served[n0:]) == sorted(f"/{name}" for name in FLUTTER_CBC_SHA256)
