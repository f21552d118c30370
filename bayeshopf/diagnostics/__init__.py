"""Posterior summaries: bifurcation bands, Hopf/fold intervals, predictive checks."""

from bayeshopf._lazy import submodule_getattr
from bayeshopf.diagnostics.bifurcation import BranchBand as BranchBand
from bayeshopf.diagnostics.bifurcation import DiagramBands as DiagramBands
from bayeshopf.diagnostics.ppc import PosteriorPredictiveCheck as PosteriorPredictiveCheck
from bayeshopf.diagnostics.summaries import Interval as Interval
from bayeshopf.diagnostics.summaries import interval as interval

__getattr__ = submodule_getattr(__name__)
