"""The one adapter between bayeshopf and ArviZ.

bayeshopf is on the ArviZ 0.x line (``arviz<0.24``, tested with 0.23):
ArviZ 1.x needs Python ≥ 3.12, which bayeshopf (Python 3.11) does not have,
and rewrites the API (``InferenceData`` becomes xarray's ``DataTree``, the
stats move to ``arviz_stats``). Every ArviZ call of the package goes through
this module, so a move to 1.x changes this file only; the saved
``posterior.nc`` has one netCDF group per InferenceData group, which
``xarray.open_datatree`` opens as well.

ArviZ is imported on first use (:func:`arviz`), not with this module: its
import takes seconds, which the sampler starts in a background thread beside
its chains (:func:`bayeshopf._preload.start`).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bayeshopf._atomic import replacing

if TYPE_CHECKING:
    import arviz as az


def arviz():
    """The ``arviz`` module, imported on first use."""
    with warnings.catch_warnings():  # the 0.2x series announces its 1.x refactor on import
        warnings.simplefilter("ignore", FutureWarning)
        import arviz as az
    return az


def write_netcdf(idata: az.InferenceData, path: str | os.PathLike[str]) -> Path:
    """Write ``idata`` to ``path`` atomically (a temporary file, then a rename)."""
    path = Path(path)
    with replacing(path) as tmp:
        idata.to_netcdf(tmp)
    return path


def read_posterior(path: str | os.PathLike[str]) -> tuple[dict, dict]:
    """Flat posterior draws and the posterior attributes from a netCDF file.

    Only the file's ``posterior`` group is read (xarray, without ArviZ).

    Returns:
        ``(samples, attrs)``: site name -> array ``(n_chains · n_draws, ...)``.
    """
    import xarray as xr

    with xr.open_dataset(path, group="posterior") as ds:
        post = ds.load()
    samples = {}
    for k, v in post.data_vars.items():
        a = np.asarray(v.values)
        samples[k] = a.reshape((-1,) + a.shape[2:])
    return samples, dict(post.attrs)


def _log_lik_idata(ll) -> az.InferenceData:
    ll = np.asarray(ll)
    return arviz().from_dict(posterior={"_": np.zeros((1, ll.shape[0]))},
                             log_likelihood={"obs": ll[None]})


def _refits(idata, held_out_log_lik):
    """ArviZ's sampling wrapper over a callback (built on first use, as ArviZ is imported)."""

    class _Refits(arviz().SamplingWrapper):
        """ArviZ's sampling wrapper over a callback ``i ↦ log p(y_i | θ_s^(−i))``.

        ``reloo`` asks the wrapper to drop observation i, refit and evaluate the
        held-out log-likelihood; here one callback does all three.
        """

        def __init__(self, idata, held_out_log_lik):
            super().__init__(model=None, idata_orig=idata)
            self._held_out = held_out_log_lik

        def check_implemented_methods(self, methods):
            # ArviZ checks by calling every method with a dummy argument, which here
            # would run a refit; all four are implemented
            return []

        def sel_observations(self, idx):
            i = int(np.ravel(idx)[0])
            return i, i

        def sample(self, modified_observed_data):
            return modified_observed_data

        def get_inference_data(self, fitted):
            return fitted

        def log_likelihood__i(self, excluded_obs, idata__i):
            import xarray as xr

            return xr.DataArray(np.asarray(self._held_out(int(excluded_obs)), dtype=float))

    return _Refits(idata, held_out_log_lik)


def _elpd(log_lik, held_out_log_lik=None, k_thresh: float = 0.7):
    """``(ELPDData, PSIS Pareto k, refitted observations)``.

    The ``ELPDData`` is PSIS-LOO's, or ``reloo``'s where Pareto k exceeds ``k_thresh``.
    """
    idata = _log_lik_idata(log_lik)
    with warnings.catch_warnings():  # large Pareto k is reported by the callers
        warnings.filterwarnings("ignore", message="Estimated shape parameter of Pareto")
        res = arviz().loo(idata, pointwise=True)
        # a copy: reloo zeroes the k of the refitted observations in place
        pareto_k = np.array(res["pareto_k"], dtype=float)
        if held_out_log_lik is None:
            return res, pareto_k, []
        refitted = [int(i) for i in np.flatnonzero(pareto_k > k_thresh)]
        warnings.filterwarnings("ignore", message="reloo is an experimental")
        return arviz().reloo(_refits(idata, held_out_log_lik), res, k_thresh=k_thresh,
                        verbose=False), pareto_k, refitted


def _loo_dict(res, pareto_k, refitted) -> dict:
    return {
        "elpd": float(res["elpd_loo"]),
        "se": float(res["se"]),
        "p_loo": float(res["p_loo"]),
        "pareto_k": [float(v) for v in pareto_k],
        "elpd_i": [float(v) for v in np.asarray(res["loo_i"])],
        "refitted": refitted,
    }


def loo(log_lik, held_out_log_lik=None, k_thresh: float = 0.7) -> dict:
    """PSIS-LOO of pointwise log-likelihoods ``(n_draws, n_obs)`` (one chain).

    Args:
        log_lik: ``log p(y_i | θ_s)`` for the posterior draws θ_s.
        held_out_log_lik: Optional ``i ↦ log p(y_i | θ_s^(−i))`` over the draws
            of a refit without observation i. When given, the observations whose
            Pareto k exceeds ``k_thresh`` get their exact leave-one-out density
            ``log mean_s p(y_i | θ_s^(−i))`` from it (ArviZ ``reloo``) instead of PSIS.
        k_thresh: Pareto k above which PSIS is not trusted.

    Returns:
        ``{"elpd", "se", "pareto_k": [...], "p_loo", "elpd_i": [...], "refitted": [i...]}``;
        ``pareto_k`` holds the PSIS values, also for the refitted observations.
    """
    return _loo_dict(*_elpd(log_lik, held_out_log_lik, k_thresh))


def compare_with_loo(log_liks: dict, held_out: dict | None = None,
                     k_thresh: float = 0.7) -> tuple[dict, dict]:
    """ArviZ ``compare`` of models by LOO, and each model's :func:`loo`.

    Args:
        log_liks: Model name → pointwise log-likelihoods ``(n_draws, n_obs)``.
        held_out: Optional model name → ``i ↦ log p(y_i | θ_s^(−i))`` (see
            :func:`loo`): exact refits where that model's Pareto k exceeds
            ``k_thresh``.
        k_thresh: Pareto k above which PSIS is not trusted.

    Returns:
        ``(table, loos)``: name → rank, elpd_loo, elpd_diff, dse, weight; and
        name → the :func:`loo` dictionary.
    """
    held_out = held_out or {}
    elpds = {name: _elpd(ll, held_out.get(name), k_thresh) for name, ll in log_liks.items()}
    table = arviz().compare({name: e[0] for name, e in elpds.items()}, ic="loo")
    rows = {
        str(name): {
            "rank": int(row["rank"]),
            "elpd_loo": float(row["elpd_loo"]),
            "elpd_diff": float(row["elpd_diff"]),
            "dse": float(row["dse"]),
            "weight": float(row["weight"]),
        }
        for name, row in table.iterrows()
    }
    loos = {name: _loo_dict(*e) for name, e in elpds.items()}
    return rows, loos


def compare(log_liks: dict) -> dict:
    """ArviZ ``compare`` of models by PSIS-LOO; returns name -> rank, elpd, dse, weight."""
    return compare_with_loo(log_liks)[0]


def chains_to_inference_data(posterior: dict, *, observed: dict | None = None,
                             constant: dict | None = None, log_likelihood: dict | None = None,
                             posterior_predictive: dict | None = None,
                             sample_stats: dict | None = None,
                             coords: dict | None = None, dims: dict | None = None,
                             extra_coords: dict | None = None,
                             attrs: dict | None = None) -> az.InferenceData:
    """InferenceData from draws by chain ``(n_chains, n_draws, ...)``.

    ``log_likelihood``, ``posterior_predictive`` and ``sample_stats`` hold draws
    by chain and draw too; ``observed`` and ``constant`` hold data without them.
    ``coords`` and ``dims`` name the axes (ArviZ's ``from_dict``);
    ``extra_coords`` adds non-index coordinates, ``name → (dim, values)``, to
    every group with that dimension (e.g. the channel each frame axis follows).
    ``attrs`` go to every group.
    """
    def arrays(d):
        return {k: np.asarray(v) for k, v in (d or {}).items()} or None

    with warnings.catch_warnings():  # 0.2x announces its 1.x refactor
        warnings.simplefilter("ignore", FutureWarning)
        idata = arviz().from_dict(
            posterior=arrays(posterior), log_likelihood=arrays(log_likelihood),
            posterior_predictive=arrays(posterior_predictive),
            sample_stats=arrays(sample_stats), observed_data=arrays(observed),
            constant_data=arrays(constant), coords=coords, dims=dims, attrs=attrs or {},
        )
    for group in idata.groups():
        ds = getattr(idata, group)
        add = {k: v for k, v in (extra_coords or {}).items() if v[0] in ds.dims}
        setattr(idata, group, ds.assign_coords(add).assign_attrs(attrs or {}))
    return idata


def read_inference_data(path: str | os.PathLike[str]) -> az.InferenceData:
    """The InferenceData of a netCDF file (all groups loaded into memory, file closed)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        return arviz().from_netcdf(str(path))
