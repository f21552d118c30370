"""NUTS on the rig's collapsed model: diagonal against dense mass matrix, long against short chains.

Run: ``python benchmarks/bench_nuts_mass.py``. From the same MAP point, 4
sequential chains for each setting; reports the mean number of leapfrog steps
per iteration (the cost, independent of the machine's load), R̂ and bulk ESS of
μ0, a2, μ_fold and w. Writes ``benchmarks/results/nuts_mass.json``. The defaults of
:class:`~bayeshopf.inference.collapsed.CollapsedSettings` were chosen from this.
"""

import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
from _common import RESULTS_DIR, atomic_write  # noqa: E402


def main():
    import jax
    import jax.numpy as jnp
    from numpyro.infer import MCMC, NUTS, init_to_value

    from bayeshopf.data import load_recordings
    from bayeshopf.features.harmonics import extract_harmonics
    from bayeshopf.inference import collapsed as ci
    from bayeshopf.inference.nuts import rhat_ess
    from bayeshopf.model import collapsed as cm

    f = extract_harmonics(load_recordings(HERE.parent.parent / "shared/data/flutter_cbc"))
    spec = ci.build_spec(f, "subcritical")
    kw = ci.model_arguments(spec, f)
    mp = ci.fit_map(kw)
    latent = {k: jnp.asarray(mp.params[k]) for k in mp.unconstrained}
    rows = []
    for dense in (False, True):
        for n in (500, 300):
            t0 = time.perf_counter()
            m = MCMC(NUTS(cm.collapsed_model, init_strategy=init_to_value(values=latent),
                          dense_mass=dense), num_warmup=n, num_samples=n, num_chains=4,
                     chain_method="sequential", progress_bar=False)
            m.run(jax.random.PRNGKey(1), extra_fields=("num_steps",), **kw)
            steps = float(np.mean(np.asarray(m.get_extra_fields()["num_steps"])))
            ch = {k: np.asarray(v) for k, v in m.get_samples(group_by_chain=True).items()
                  if k in ("mu0", "a2", "mu_fold", "w_unfold")}
            rows.append({"dense_mass": dense, "num_warmup": n, "num_samples": n,
                         "mean_leapfrog_steps": steps, "wall_s": time.perf_counter() - t0,
                         "sites": {k: {"r_hat": r, "ess_bulk": e}
                                   for k, (r, e) in rhat_ess(ch).items()}})
            print(rows[-1], flush=True)
    atomic_write(RESULTS_DIR / "nuts_mass.json", json.dumps(rows, indent=1))


if __name__ == "__main__":
    from _common import exit_on_help

    exit_on_help(__doc__)
    main()
