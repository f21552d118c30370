"""Recordings -> phase-aligned time-Fourier coefficients of their orbits in a common frame."""

from bayeshopf._lazy import submodule_getattr
from bayeshopf.features.frame import PlanarFrame as PlanarFrame
from bayeshopf.features.harmonics import HarmonicFeatures as HarmonicFeatures
from bayeshopf.features.harmonics import extract_harmonics as extract_harmonics

__getattr__ = submodule_getattr(__name__)
