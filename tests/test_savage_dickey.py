"""Savage–Dickey Bayes factors of nested models, against exact linear-Gaussian evidences.

The toy: whitened residuals linear in the unknowns, ``e = (y - A z - b ζ)/σ``
with standard normal priors on ``z`` and ``ζ`` (half-normal for a bounded
coefficient), whose evidences are Gaussian integrals written here
independently of the package: ``y ~ N(0, σ²I + AAᵀ + f² bbᵀ)`` in closed
form, and by quadrature (``scipy.integrate``) for the half-normal priors.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import integrate, special, stats

from bayeshopf.discrepancy.calibration import _classes, _log_priors, _probabilities
from bayeshopf.discrepancy.evidence import laplace_evidence
from bayeshopf.discrepancy.nested import (
    SCALES,
    SD_RANGE,
    CoefficientPosterior,
    class_bayes_factors,
    gaussian_marginal,
    log_bayes_factor,
    mixture_log_bf,
    nested_log_z,
    sensitivity,
    use_savage_dickey,
)
from bayeshopf.discrepancy.render import _bayes_markdown
from bayeshopf.discrepancy.verdict import with_bayes_factors, with_notes

RNG = np.random.default_rng(7)
N, D = 14, 3
A = RNG.normal(size=(N, D)) * 0.8
B1 = RNG.normal(size=N) * 0.6
B2 = RNG.normal(size=N) * 0.5
Y = A @ RNG.normal(size=D) + 2.0 * B1 + 1.0 * B2 + RNG.normal(size=N)


def _log_gauss(y, cov):
    return float(stats.multivariate_normal(np.zeros(y.size), cov).logpdf(y))


def _exact_log_z(cols, f=1.0, sigma=1.0):
    """log Z with standard normal z, N(0, f²) coefficients on ``cols``: closed form."""
    cov = sigma**2 * np.eye(N) + A @ A.T + sum(f**2 * np.outer(c, c) for c in cols)
    return _log_gauss(Y, cov)


def _stacked(x, cols, sigma=1.0):
    """E and G of the toy at ``x = (z, ζ...)`` (prior rows included)."""
    k = len(cols)
    M = np.column_stack([A, *cols]) if k else A
    E = np.concatenate([(Y - M @ x) / sigma, x])
    G = np.vstack([-M / sigma, np.eye(D + k)])
    return E, G


def _posterior(cols, positive, x=None, sigma=1.0):
    x = np.linspace(-0.4, 0.6, D + len(cols)) if x is None else x
    m, C = gaussian_marginal(*_stacked(x, cols, sigma), x, len(cols))
    return CoefficientPosterior(np.ones(1), m[None], C[None], tuple(positive))


def _half_normal_log_bf(cols, f=1.0):
    """log Z_k − log Z_P for half-normal N⁺(0, f²) coefficients on ``cols``, by quadrature."""
    S = np.eye(N) + A @ A.T
    Si = np.linalg.inv(S)

    def ratio(*zeta):
        mu = sum(z * c for z, c in zip(zeta, cols, strict=True))
        # N(y; mu, S) / N(y; 0, S), times the half-normal densities
        lr = float(Y @ Si @ mu - 0.5 * mu @ Si @ mu)
        return np.exp(lr) * np.prod([2 * stats.norm.pdf(z, 0, f) for z in zeta])

    if len(cols) == 1:
        val, _ = integrate.quad(ratio, 0, np.inf, epsabs=0, epsrel=1e-12, limit=200)
    else:
        val, _ = integrate.dblquad(lambda a, b: ratio(b, a), 0, 12 * f, 0, 12 * f,
                                   epsabs=0, epsrel=1e-10)
    return float(np.log(val))


# ------------------------------------------------------------------------- exactness


@pytest.mark.parametrize("x", [None, np.array([1.0, -2.0, 0.5, 3.0])])
def test_savage_dickey_is_the_exact_log_bayes_factor_of_a_linear_gaussian_model(x):
    # wherever the fit stopped (x), the ratio is exact for linear residuals
    exact = _exact_log_z([B1]) - _exact_log_z([])
    assert log_bayes_factor(_posterior([B1], [False], x)) == pytest.approx(exact, abs=1e-10)
    assert abs(exact) > 1.0                                   # a non-trivial factor


def test_a_pair_against_its_single_term_and_against_the_parameters():
    post = _posterior([B1, B2], [False, False])
    exact_pair = _exact_log_z([B1, B2])
    assert log_bayes_factor(post) == pytest.approx(exact_pair - _exact_log_z([]), abs=1e-10)
    assert log_bayes_factor(post.sub([1])) == pytest.approx(
        exact_pair - _exact_log_z([B1]), abs=1e-10)
    assert log_bayes_factor(post.sub([0])) == pytest.approx(
        exact_pair - _exact_log_z([B2]), abs=1e-10)


def test_a_half_normal_coefficient_against_quadrature():
    exact = _half_normal_log_bf([B1])
    assert log_bayes_factor(_posterior([B1], [True])) == pytest.approx(exact, abs=1e-9)
    # a coefficient the data push below 0: the truncated marginal at its bound
    neg = -B1
    assert log_bayes_factor(_posterior([neg], [True])) == pytest.approx(
        _half_normal_log_bf([neg]), abs=1e-9)
    assert log_bayes_factor(_posterior([neg], [True])) < -0.5


def test_two_half_normal_coefficients_against_a_double_integral():
    exact = _half_normal_log_bf([B1, B2])
    assert log_bayes_factor(_posterior([B1, B2], [True, True])) == pytest.approx(exact,
                                                                                  abs=1e-7)


def _mixed_over_sigma(sigmas, x):
    """The term's marginal mixed over a grid of σ, weighted as the package weights τ:
    Laplace evidence plus the −Σ log σ normaliser."""
    lz, ms, Cs = [], [], []
    for s in sigmas:
        E, G = _stacked(x, [B1], s)
        lz.append(laplace_evidence(E, G)[0] - N * np.log(s))
        m, C = gaussian_marginal(E, G, x, 1)
        ms.append(m)
        Cs.append(C)
    w = np.exp(np.array(lz) - max(lz))
    return CoefficientPosterior(w / w.sum(), np.array(ms), np.array(Cs), (False,))


def test_model_error_mixed_over_the_larger_models_weights():
    # τ on a grid with a uniform prior: Z_M = mean over τ of Z_M(τ), exact per τ
    sigmas = np.array([0.7, 1.0, 1.6, 2.5])
    lzk = np.array([_exact_log_z([B1], sigma=s) for s in sigmas])
    lzp = np.array([_exact_log_z([], sigma=s) for s in sigmas])
    exact = float(special.logsumexp(lzk) - special.logsumexp(lzp))
    post = _mixed_over_sigma(sigmas, np.linspace(-0.4, 0.6, D + 1))
    assert log_bayes_factor(post) == pytest.approx(exact, abs=1e-10)
    # the weights matter: the largest σ alone is not the answer
    assert abs(lzk[-1] - lzp[-1] - exact) > 0.1


# ------------------------------------------------------------------- prior-scale band


@pytest.mark.parametrize("f", [0.5, 2.0])
def test_the_analytic_band_equals_refitting_with_the_scaled_prior(f):
    post = _posterior([B1], [False])
    exact = _exact_log_z([B1], f=f) - _exact_log_z([])
    assert log_bayes_factor(post, f) == pytest.approx(exact, abs=1e-10)
    band = sensitivity(post, (f,))
    assert band[f] == pytest.approx(exact - (_exact_log_z([B1]) - _exact_log_z([])),
                                    abs=1e-10)


@pytest.mark.parametrize("f", [0.5, 2.0])
def test_the_band_of_a_half_normal_coefficient_and_of_a_pair(f):
    assert log_bayes_factor(_posterior([B1], [True]), f) == pytest.approx(
        _half_normal_log_bf([B1], f), abs=1e-9)
    post = _posterior([B1, B2], [False, False])
    exact = _exact_log_z([B1, B2], f=f) - _exact_log_z([])
    assert log_bayes_factor(post, f) == pytest.approx(exact, abs=1e-10)


def test_the_band_mixed_over_model_error():
    sigmas = np.array([0.8, 1.3, 2.0])
    post = _mixed_over_sigma(sigmas, np.zeros(D + 1))
    for f in (0.5, 2.0):
        exact = float(special.logsumexp([_exact_log_z([B1], f=f, sigma=s) for s in sigmas])
                      - special.logsumexp([_exact_log_z([], sigma=s) for s in sigmas]))
        assert log_bayes_factor(post, f) == pytest.approx(exact, abs=1e-10)


# ------------------------------------------------------------------ where SD is used


def _fit(name, post, *, refined=True, penalty=0.0, log_z=-100.0):
    return SimpleNamespace(term=SimpleNamespace(name=name), coefficients=post,
                           refined=refined, penalty=penalty, log_z_laplace=log_z)


def test_savage_dickey_only_for_a_confirmed_full_fit_near_zero():
    near = _posterior([B1 * 0.05], [False])                 # 0 within the posterior
    far = CoefficientPosterior(np.ones(1), np.array([[10.0]]), np.array([[[1.0]]]), (False,))
    assert near.distance <= SD_RANGE < far.distance
    assert use_savage_dickey(near, True)
    assert not use_savage_dickey(near, False)                # screened: its own evidence
    assert not use_savage_dickey(far, True)
    # a bounded coefficient whose centre is far below 0 sits at its bound: local
    below = CoefficientPosterior(np.ones(1), np.array([[-10.0]]), np.array([[[1.0]]]),
                                 (True,))
    assert use_savage_dickey(below, True)


def test_a_parameters_fit_that_stopped_short_does_not_lose_to_a_nested_term():
    # the term's coefficient sits at 0 within its posterior; M_P's own evidence is 30 nats
    # low (it stopped short), and the term's own Laplace evidence is that of a better mode
    post = _posterior([B1 * 0.01], [False])
    lzp_true = -100.0
    f = _fit("t", post, log_z=lzp_true + 1.0)
    lz, how = nested_log_z(lzp_true - 30.0, [f], [])
    assert how["t"] == "savage-dickey vs parameters"
    assert lz["t"] - (lzp_true - 30.0) == pytest.approx(mixture_log_bf(post))
    assert lz["t"] - (lzp_true - 30.0) < 0.5                 # no credit for M_P's stop
    # the larger model's polish charge is kept
    lz, how = nested_log_z(lzp_true - 30.0, [_fit("t", post, penalty=5.0, log_z=-99.0)], [])
    assert lz["t"] == pytest.approx(lzp_true - 30.0 + mixture_log_bf(post) - 5.0)
    # screened: the fit keeps its own evidence
    lz, how = nested_log_z(lzp_true - 30.0, [_fit("t", post, refined=False, log_z=-99.0)], [])
    assert how["t"] == "laplace"
    assert lz["t"] == pytest.approx(-99.0 + mixture_log_bf(post) - log_bayes_factor(post))


def test_a_pair_is_nested_in_its_more_probable_single_term():
    post = _posterior([B1, B2], [False, False])
    # each single keeps its own (here exact) evidence where Savage–Dickey is not used
    singles = [_fit("a", _posterior([B1], [False]), log_z=_exact_log_z([B1])),
               _fit("b", _posterior([B2], [False]), log_z=_exact_log_z([B2]))]
    pair = SimpleNamespace(name="a+b", terms=(singles[0].term, singles[1].term),
                           coefficients=post, refined=True, penalty=0.0, log_z_laplace=-1e3)
    lzp = _exact_log_z([])
    lz, how = nested_log_z(lzp, singles, [pair])
    k = "a" if lz["a"] > lz["b"] else "b"
    assert how["a+b"] == f"savage-dickey vs {k}"
    # the scale-free prior (nested.py): each single's evidence is its exact evidence
    # averaged over the factor f of its prior scale ...
    for name, col in (("a", B1), ("b", B2)):
        assert lz[name] == pytest.approx(special.logsumexp(
            [_exact_log_z([col], f) for f in SCALES]) - np.log(len(SCALES)), abs=1e-9)
    # ... and the pair's adds the second coefficient's exact Bayes factor averaged over its
    # own f, the first at its library scale
    first, second = (B1, B2) if k == "a" else (B2, B1)

    def log_z_two(f):
        cov = np.eye(N) + A @ A.T + np.outer(first, first) + f**2 * np.outer(second, second)
        return _log_gauss(Y, cov)

    bf = special.logsumexp([log_z_two(f) for f in SCALES]) - np.log(len(SCALES)) \
        - _exact_log_z([first])
    assert lz["a+b"] == pytest.approx(lz[k] + bf, abs=1e-9)


# --------------------------------------------------------------- class Bayes factors


def test_class_bayes_factors_times_prior_odds_are_the_posterior_odds():
    fits = [SimpleNamespace(term=SimpleNamespace(name=n), log_z=v)
            for n, v in (("t1", 3.0), ("t2", -1.0), ("t3", 0.5))]
    pairs = [SimpleNamespace(name="t1+t2", log_z=4.0)]
    log_z = {"none": -2.0, "parameters": 1.0}
    probs = _probabilities(log_z, fits, pairs, scan=True, pairs=True, n=3)
    cls = _classes(probs, fits, pairs)
    lp = _log_priors(fits, pairs, scan=True, pairs=True, n=3)
    allz = {**log_z, **{f.term.name: f.log_z for f in fits}, "t1+t2": 4.0}
    bf = class_bayes_factors(lp, allz, {"none": ["none"], "parameters off": ["parameters"],
                                        "term missing": ["t1", "t2", "t3", "t1+t2"]})
    for c, o in (("term missing", "none"), ("term missing", "parameters off"),
                 ("parameters off", "none")):
        odds = bf["log_bayes_factor"][c][o] + np.log(bf["prior"][c] / bf["prior"][o])
        assert odds == pytest.approx(np.log(cls[c] / cls[o]), abs=1e-12)
    assert bf["log_bayes_factor"]["parameters off"]["none"] == pytest.approx(3.0)
    # normalised over the models compared: 3 singles at 1/18, 1 pair of 3 at 1/18
    assert bf["prior"]["none"] == pytest.approx((1 / 3) / (2 / 3 + 3 / 18 + 1 / 18))
    assert sum(bf["prior"].values()) == pytest.approx(1.0)


@pytest.mark.parametrize(("scales", "decided"), [({"0.5": 0.9, "2.0": -0.4}, True),
                                                  ({"0.5": 3.1, "2.0": 1.2}, False)])
def test_the_verdict_says_when_the_prior_scales_decide(scales, decided):
    lb = {"none": {"parameters off": -5.0, "term missing": -7.0},
          "parameters off": {"none": 5.0, "term missing": -2.0},
          "term missing": {"none": 7.0, "parameters off": 2.0}}
    bayes = {"prior": {"none": 0.4, "parameters off": 0.4, "term missing": 0.2},
             "log_evidence": {}, "log_bayes_factor": lb}
    band = {"model": "t", "label": "a term", "evidence": "laplace", "log_bayes_factor": 2.0,
            "scales": scales}
    v = with_bayes_factors({"kind": "term missing", "model": "t", "sentence": "S."}, bayes,
                           [band])
    assert ("rests on the terms' prior scales" in v["sentence"]) is decided
    lo, hi = min(2.0, *scales.values()), max(2.0, *scales.values())
    assert f"a term: log B 2.0 [{lo:.1f}, {hi:.1f}] over prior scales ×0.5–×2" in v["sentence"]
    # a class is not compared with itself; the Markdown table has every class
    assert "none" not in v["bayes_factors"]["log_bayes_factor"]["none"]
    md = "\n".join(_bayes_markdown(v))
    assert "| term missing | 0.2 | 7.0 | 2.0 |" in md and "| none | 0.4 | – | -5.0 |" in md


def test_an_unexplained_verdict_gives_the_discrepancys_bayes_factor():
    lb = {"none": {"parameters off": -5.0, "unexplained": -9.0, "term missing": -7.0},
          "parameters off": {"none": 5.0, "unexplained": -4.0, "term missing": -2.0},
          "unexplained": {"none": 9.0, "parameters off": 4.0, "term missing": 2.0},
          "term missing": {"none": 7.0, "parameters off": 2.0, "unexplained": -2.0}}
    bayes = {"prior": {"none": 0.3, "parameters off": 0.3, "unexplained": 0.3,
                       "term missing": 0.1}, "log_evidence": {}, "log_bayes_factor": lb}
    v = with_bayes_factors({"kind": "unexplained", "model": "unexplained", "sentence": "S."},
                           bayes, [])
    assert v["sentence"] == ("S. Apart from the prior odds, the log Bayes factor of the smooth "
                             "discrepancy against parameters off is 4.0, of a missing term 2.0.")
    assert v["bayes_factors"]["log_bayes_factor"]["unexplained"] == {"none": 9.0,
                                                                      "parameters off": 4.0}


def test_the_preparations_notes_close_the_sentence():
    v = with_notes({"sentence": "S. Apart from the prior odds, 4.0."},
                   ["stable branch: no LCO at U = 14.9 m/s", "unstable branch: none either."])
    assert v["sentence"] == ("S. Apart from the prior odds, 4.0. Note: stable branch: no LCO at "
                             "U = 14.9 m/s; unstable branch: none either.")
    assert with_notes({"sentence": "S."}, [])["sentence"] == "S."
