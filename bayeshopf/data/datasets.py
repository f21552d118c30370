"""Published data sets, read from a local folder or downloaded on request.

The flutter-rig recordings of Lee et al. (control-based continuation in a wind
tunnel) are published in the MIT-licensed repository Kyounghyunlee/ML_Hopf
(``src/measured_data/``). bayeshopf never ships them: :func:`flutter_cbc` reads
them from a folder you name, or downloads them into pooch's cache with their
SHA-256 hashes pinned below.

Environment variables: ``BAYESHOPF_FLUTTER_CBC`` names a local folder with the
files (used instead of a download); ``BAYESHOPF_FLUTTER_CBC_URL`` replaces the
download's base URL (a mirror, e.g. ``http://localhost:8000/``);
``BAYESHOPF_DATA_DIR`` moves the download folder from pooch's user cache
(``~/.cache/bayeshopf`` on Linux) to ``$BAYESHOPF_DATA_DIR/flutter_cbc``.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from bayeshopf.data._common import one_line as _one_line
from bayeshopf.data.matfile import read_cbc_mat
from bayeshopf.data.recording import RecordingSet
from bayeshopf.errors import DataError

__all__ = ["DATA_DIR_ENV", "FLUTTER_CBC_ENV", "FLUTTER_CBC_SHA256", "FLUTTER_CBC_URL",
           "FLUTTER_CBC_URL_ENV", "download_flutter_cbc", "flutter_cbc"]

FLUTTER_CBC_ENV = "BAYESHOPF_FLUTTER_CBC"
FLUTTER_CBC_URL_ENV = "BAYESHOPF_FLUTTER_CBC_URL"
DATA_DIR_ENV = "BAYESHOPF_DATA_DIR"
FLUTTER_CBC_URL = "https://github.com/Kyounghyunlee/ML_Hopf/raw/main/src/measured_data/"
FLUTTER_CBC_SHA256: dict[str, str] = {
    "CBC_stable_v14_9.mat": "1f4656b7737b3bbb9a00528d9dbd61dccad9e3345ad62cf9423b1db644086985",
    "CBC_stable_v15_6.mat": "96b627284c62a6a2a221a21ac18d1d23a97fc220a16c819f24f94accfba29d9b",
    "CBC_stable_v16_5.mat": "92692963ae2eaa4a53a871b7093318194e0c3ee68085c0b1a8be811f8086eec0",
    "CBC_stable_v17_3.mat": "15ac1986d2fea50adac18254d058f8c3342cbc8a6fdd275951cdb4623af6889d",
    "CBC_unstable_v14_9.mat": "deee3acdf2aea60ea5773c6a47504085a232306e463430f451d54074ef5dc9bc",
    "CBC_unstable_v15_6.mat": "35fc1405c87bd44a49919cd1460ced80c11a29429bf7912fd59863ce95e5bb01",
    "CBC_unstable_v16_5.mat": "317e668d1fdec643ce6e8128f30a0bb0ca838c3eacfb6aaca29de01e2270ecd8",
}


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _local_files(folder: Path, origin: str) -> list[Path]:
    """The seven files in ``folder``, each checked against its pinned hash."""
    if not folder.is_dir():
        what = "a file" if folder.exists() else "nothing"
        raise DataError(
            f"{folder}: flutter_cbc data folder ({origin}) holding the 7 CBC_*.mat files "
            f"expected; found {what} (to get them: flutter_cbc(download=True), or copy the "
            "files of github.com/Kyounghyunlee/ML_Hopf src/measured_data into a folder)"
        )
    files = []
    for name, expected in FLUTTER_CBC_SHA256.items():
        path = folder / name
        if not path.is_file():
            raise DataError(f"{name}: expected in the flutter_cbc folder {folder}; not found "
                            "(flutter_cbc(download=True) fetches all 7)")
        try:
            found = _sha256(path)
        except OSError as exc:
            raise DataError(f"{name}: cannot be read ({_one_line(exc)})") from exc
        if found != expected:
            raise DataError(
                f"{name}: SHA-256 {expected[:12]}... expected (the published file); "
                f"found {found[:12]}..."
            )
        files.append(path)
    return files


def _base_url() -> str:
    """``$BAYESHOPF_FLUTTER_CBC_URL`` (a mirror) if set, else :data:`FLUTTER_CBC_URL`."""
    url = os.environ.get(FLUTTER_CBC_URL_ENV, "").strip() or FLUTTER_CBC_URL
    return url if url.endswith("/") else url + "/"


def _download(folder: str | os.PathLike[str] | None = None) -> list[Path]:
    """Fetch the seven files into ``folder`` or the cache (hash-checked by pooch).

    Files already there with the pinned hash are not fetched again.
    """
    import pooch

    if folder is not None:
        folder = Path(folder).expanduser()
    elif os.environ.get(DATA_DIR_ENV, "").strip():
        folder = Path(os.environ[DATA_DIR_ENV].strip()).expanduser() / "flutter_cbc"
    else:
        folder = Path(pooch.os_cache("bayeshopf")) / "flutter_cbc"
    base = _base_url()
    files = []
    for name, sha in FLUTTER_CBC_SHA256.items():
        url = base + name
        try:
            got = pooch.retrieve(
                url, known_hash=f"sha256:{sha}", fname=name, path=folder, progressbar=False
            )
        except Exception as exc:  # network, HTTP and hash-mismatch errors alike
            raise DataError(
                f"{name}: download from {url} failed ({_one_line(exc)}); set "
                f"{FLUTTER_CBC_URL_ENV} to a mirror or {FLUTTER_CBC_ENV} to a local copy"
            ) from exc
        files.append(Path(got))
    return files


def download_flutter_cbc(to: str | os.PathLike[str] | None = None) -> Path:
    """Download the seven files (about 11 MB, SHA-256 checked) and return their folder.

    Args:
        to: Folder to download into; by default ``$BAYESHOPF_DATA_DIR/flutter_cbc``
            or pooch's user cache (``~/.cache/bayeshopf/flutter_cbc`` on Linux).
            The base URL is ``$BAYESHOPF_FLUTTER_CBC_URL`` if set, else the
            authors' repository.

    Returns:
        The folder holding the seven ``CBC_*.mat`` files (give it to
        :func:`flutter_cbc` or ``bayeshopf fit``).

    Raises:
        DataError: If a download fails or a file's hash differs.
    """
    return _download(to)[0].parent


def flutter_cbc(
    path: str | os.PathLike[str] | None = None, *, download: bool = False
) -> RecordingSet:
    """The wind-tunnel flutter rig's seven CBC limit-cycle recordings.

    Four stable-branch LCOs (14.9, 15.6, 16.5, 17.3 m/s) and three unstable-branch
    LCOs stabilised by control-based continuation (14.9, 15.7, 16.5 m/s); see
    :func:`~bayeshopf.data.matfile.read_cbc_mat` for channels and units. The data are
    taken from, in order: ``path``; the folder named by the environment variable
    ``BAYESHOPF_FLUTTER_CBC``; a download (:func:`download_flutter_cbc`) when
    ``download`` is true. Local files are checked against the pinned
    SHA-256 hashes.

    Args:
        path: Folder holding the seven ``CBC_*.mat`` files.
        download: Download the files (about 11 MB) from GitHub, or from
            ``$BAYESHOPF_FLUTTER_CBC_URL``, if no folder is given by ``path`` or the
            environment; files already downloaded are reused.

    Returns:
        The recordings, stable branch first, each branch sorted by airspeed.

    Raises:
        DataError: If no source is given, the folder or a file is missing, a
            file's hash differs from the published one, or a download fails.
    """
    origin = "path="
    if path is None and os.environ.get(FLUTTER_CBC_ENV, "").strip():
        path, origin = os.environ[FLUTTER_CBC_ENV].strip(), f"from ${FLUTTER_CBC_ENV}"
    if path is not None:
        files = _local_files(Path(path).expanduser(), origin)
    elif download:
        files = _download()
    else:
        raise DataError(
            "flutter_cbc: a data source expected; found none. Pass path=<folder with the 7 "
            f"CBC_*.mat files>, set {FLUTTER_CBC_ENV} to that folder, or use download=True "
            f"(fetches them from {_base_url()})"
        )
    return read_cbc_mat(files)
