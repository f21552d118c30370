"""Missing physics: where a simulator and LCO recordings disagree, and which term it lacks.

Beside the main flow (the hybrid fit): :func:`analyse` compares recordings
with a :class:`~bayeshopf.simulators.System`, locates the mismatch, gives
every candidate term of a library of missing physics (stiffness, freeplay,
friction and damping nonlinearities on each observed mechanical coordinate)
a posterior probability and a coefficient with a 90% interval, adds the most
probable one and shows the fit before and after, with a one-sentence verdict.
``bayeshopf discrepancy DATA --simulator NAME --out DIR`` runs it from the
shell; ``bayeshopf simulate ... --effect NAME --effect-value X`` plants a hidden
effect in simulated recordings to test it blind.

:func:`calibrate` first calibrates the parameters a simulator declares
uncertain (``System.uncertain``) as nuisance parameters, then fits each term
(and pairs of terms) jointly with them, with the model error inferred, and
tells "the parameters are off" from "a term is missing" and from
"unexplained", a smooth discrepancy no term accounts for
(:mod:`bayeshopf.discrepancy.calibration`, :mod:`bayeshopf.discrepancy.unexplained`).
:func:`analyse` and the command
use it by default for such systems (``calibrate=False``, ``--no-calibration``:
every parameter nominal, single terms).

Its modules, in the order the analysis uses them: ``features``,
``terms``, ``orbits``, ``select`` (single terms, every parameter
nominal), ``prepare`` (what both analyses start from), ``locate``,
``stages`` (one model's fit), ``single`` and ``calibrated``
(the two analyses' reports), ``calibration`` with ``problem``,
``evidence``, ``fitting``, ``nested``, ``unexplained``, ``records`` and
``verdict``,
``render`` (``report.md``), ``analysis`` (the front door),
``effects`` (planted effects for blind tests).
"""

from bayeshopf._lazy import submodule_getattr
from bayeshopf.discrepancy.analysis import DiscrepancyReport as DiscrepancyReport
from bayeshopf.discrepancy.analysis import analyse as analyse
from bayeshopf.discrepancy.calibration import CalibrationReport as CalibrationReport
from bayeshopf.discrepancy.calibration import calibrate as calibrate
from bayeshopf.discrepancy.effects import effect_names as effect_names
from bayeshopf.discrepancy.effects import simulate_with_effect as simulate_with_effect
from bayeshopf.discrepancy.effects import with_effect as with_effect
from bayeshopf.discrepancy.terms import KINDS as KINDS
from bayeshopf.discrepancy.terms import Term as Term
from bayeshopf.discrepancy.terms import library as library

__getattr__ = submodule_getattr(__name__)
