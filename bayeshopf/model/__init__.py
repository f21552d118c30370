"""The model: the normal form, the collapsed hybrid model and its pieces.

:mod:`~bayeshopf.model.normal_form` (the mechanistic part),
:mod:`~bayeshopf.model.spec` (the model's structure and the LCO radius),
:mod:`~bayeshopf.model.marginal` (the collapsed Gaussian),
:mod:`~bayeshopf.model.frequency` (the phase speed),
:mod:`~bayeshopf.model.discrepancy` (the model discrepancy),
:mod:`~bayeshopf.model.bifurcation_shift` (its twin in μ at the Hopf point and the fold),
:mod:`~bayeshopf.model.horizontal` (experiments: the diagram's curve with a Gaussian
process in its curvature, or with a window in its curvature at the fold),
:mod:`~bayeshopf.model.network_kernel` (the map's network at infinite width),
:mod:`~bayeshopf.model.extrapolation` (the extra model error away from the recordings of
the model without the discrepancy),
:mod:`~bayeshopf.model.collapsed` (the NumPyro model, which re-exports the others' names) and
:mod:`~bayeshopf.model.prior_predictive` (data sets drawn from its prior).
"""


from bayeshopf._lazy import submodule_getattr

__getattr__ = submodule_getattr(__name__)
