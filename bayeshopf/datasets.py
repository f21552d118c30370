"""Built-in datasets as ``bayeshopf.datasets.<name>()`` (see :mod:`bayeshopf.data.datasets`).

* :func:`flutter_cbc` — the wind-tunnel flutter rig's 7 CBC recordings
  (a local folder, ``$BAYESHOPF_FLUTTER_CBC``, or a download with pinned SHA-256);
  :func:`download_flutter_cbc` only downloads them and returns their folder.
"""

from bayeshopf.data.datasets import FLUTTER_CBC_ENV, download_flutter_cbc, flutter_cbc

__all__ = ["FLUTTER_CBC_ENV", "download_flutter_cbc", "flutter_cbc"]
