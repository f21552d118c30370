"""Posterior summaries: bifurcation bands, Hopf/fold intervals, predictive checks."""

from bayeshopf.diagnostics.bifurcation import BifurcationDiagram as BifurcationDiagram
from bayeshopf.diagnostics.bifurcation import BranchBand as BranchBand
from bayeshopf.diagnostics.ppc import PosteriorPredictiveCheck as PosteriorPredictiveCheck
from bayeshopf.diagnostics.summaries import Interval as Interval
from bayeshopf.diagnostics.summaries import interval as interval
