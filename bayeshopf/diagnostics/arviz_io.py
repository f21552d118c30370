"""The one adapter between bayeshopf and ArviZ.

On Python 3.11 pip resolves ArviZ 0.2x; its 1.x rewrite changes the API, so
every ArviZ call of the package goes through this module.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from pathlib import Path

import numpy as np

with warnings.catch_warnings():  # the 0.2x series announces its 1.x refactor on import
    warnings.simplefilter("ignore", FutureWarning)
    import arviz as az


def to_inference_data(
    samples: dict,
    *,
    observed: dict | None = None,
    predictive: dict | None = None,
    constant: dict | None = None,
    attrs: dict | None = None,
) -> az.InferenceData:
    """InferenceData with one chain from flat posterior draws.

    Args:
        samples: Site name -> draws with leading axis ``n_draws``.
        observed: Observed data (no draw axis).
        predictive: Posterior predictive draws, leading axis ``n_draws``.
        constant: Constant data (covariates such as μ).
        attrs: Attributes stored on the posterior group.
    """

    def chain(d):
        return {k: np.asarray(v)[None] for k, v in (d or {}).items()}

    idata = az.from_dict(
        posterior=chain(samples),
        posterior_predictive=chain(predictive) or None,
        observed_data={k: np.asarray(v) for k, v in (observed or {}).items()} or None,
        constant_data={k: np.asarray(v) for k, v in (constant or {}).items()} or None,
        attrs=attrs or {},
    )
    return idata


def write_netcdf(idata: az.InferenceData, path: str | os.PathLike[str]) -> Path:
    """Write ``idata`` to ``path`` atomically (a temporary file, then a rename)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        idata.to_netcdf(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def read_posterior(path: str | os.PathLike[str]) -> tuple[dict, dict]:
    """Flat posterior draws and the posterior attributes from a netCDF file.

    Returns:
        ``(samples, attrs)``: site name -> array ``(n_chains · n_draws, ...)``.
    """
    idata = az.from_netcdf(str(path))
    post = idata.posterior
    samples = {}
    for k, v in post.data_vars.items():
        a = np.asarray(v.values)
        samples[k] = a.reshape((-1,) + a.shape[2:])
    return samples, dict(post.attrs)


def loo(log_lik) -> dict:
    """PSIS-LOO of pointwise log-likelihoods ``(n_draws, n_obs)`` (one chain).

    Returns:
        ``{"elpd": ..., "se": ..., "pareto_k": [...], "p_loo": ...}``.
    """
    ll = np.asarray(log_lik)
    idata = az.from_dict(posterior={"_": np.zeros((1, ll.shape[0]))},
                         log_likelihood={"obs": ll[None]})
    with warnings.catch_warnings():  # large Pareto k is reported by the callers
        warnings.filterwarnings("ignore", message="Estimated shape parameter of Pareto")
        res = az.loo(idata, pointwise=True)
    return {
        "elpd": float(res["elpd_loo"]),
        "se": float(res["se"]),
        "p_loo": float(res["p_loo"]),
        "pareto_k": [float(k) for k in np.asarray(res["pareto_k"])],
    }


def compare(log_liks: dict) -> dict:
    """ArviZ ``compare`` of models by PSIS-LOO; returns name -> rank, elpd, dse, weight."""
    data = {
        name: az.from_dict(posterior={"_": np.zeros((1, np.shape(ll)[0]))},
                           log_likelihood={"obs": np.asarray(ll)[None]})
        for name, ll in log_liks.items()
    }
    with warnings.catch_warnings():  # large Pareto k is reported by the callers
        warnings.filterwarnings("ignore", message="Estimated shape parameter of Pareto")
        table = az.compare(data, ic="loo")
    return {
        str(name): {
            "rank": int(row["rank"]),
            "elpd_loo": float(row["elpd_loo"]),
            "elpd_diff": float(row["elpd_diff"]),
            "dse": float(row["dse"]),
            "weight": float(row["weight"]),
        }
        for name, row in table.iterrows()
    }
