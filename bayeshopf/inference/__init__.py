"""Inference on the collapsed model.

:mod:`~bayeshopf.inference.collapsed` runs the stages and re-exports their
names: the settings (:mod:`~bayeshopf.inference.settings`), the model's compiled
programs (:mod:`~bayeshopf.inference.programs`), the deterministic start, MAP
and Laplace covariance (:mod:`~bayeshopf.inference.optimum`), NUTS
(:mod:`~bayeshopf.inference.nuts`), importance sampling from the Laplace
approximation (:mod:`~bayeshopf.inference.importance`), SVI
(:mod:`~bayeshopf.inference.svi`), the
devices items are spread over (:mod:`~bayeshopf.inference.devices`) and the
compiled-program cache (:mod:`~bayeshopf.inference.cache`).
:mod:`~bayeshopf.inference.channels` fits further channels against a fit.
"""


from bayeshopf._lazy import submodule_getattr

__getattr__ = submodule_getattr(__name__)
