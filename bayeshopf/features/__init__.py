"""Recordings -> Fourier features of their orbits in a common planar frame."""

from bayeshopf.features.frame import PlanarFrame as PlanarFrame
from bayeshopf.features.orbits import DEFAULT_N_HARMONICS as DEFAULT_N_HARMONICS
from bayeshopf.features.orbits import OrbitFeatures as OrbitFeatures
from bayeshopf.features.orbits import amplitude_from_coeffs as amplitude_from_coeffs
from bayeshopf.features.orbits import extract_features as extract_features
