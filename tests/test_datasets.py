from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pooch
import pytest

from bayeshopf.data import datasets
from bayeshopf.data.datasets import FLUTTER_CBC_ENV, FLUTTER_CBC_SHA256, flutter_cbc
from bayeshopf.errors import DataError

CBC_DIR = (Path(__file__).parents[1] / ".." / "shared" / "data" / "flutter_cbc").resolve()
needs_cbc = pytest.mark.skipif(
    not CBC_DIR.is_dir(), reason=f"flutter CBC recordings not found at {CBC_DIR}"
)


@pytest.fixture(autouse=True)
def no_network(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(FLUTTER_CBC_ENV, raising=False)

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
