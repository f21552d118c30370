"""LCO recordings: containers, readers and writers, and published data sets."""

from __future__ import annotations

from bayeshopf._lazy import submodule_getattr
from bayeshopf.data.convergence import Convergence as Convergence
from bayeshopf.data.datasets import flutter_cbc as flutter_cbc
from bayeshopf.data.io import load_recordings as load_recordings
from bayeshopf.data.io import read_cbc_mat as read_cbc_mat
from bayeshopf.data.io import read_interchange as read_interchange
from bayeshopf.data.io import read_recordings as read_recordings
from bayeshopf.data.io import write_interchange as write_interchange
from bayeshopf.data.recording import Recording as Recording
from bayeshopf.data.recording import RecordingSet as RecordingSet
from bayeshopf.data.rig import ChannelSpec as ChannelSpec
from bayeshopf.data.rig import RigDescription as RigDescription
from bayeshopf.data.screening import converged_only as converged_only
from bayeshopf.data.screening import convergence_report as convergence_report
from bayeshopf.data.screening import unconverged as unconverged

__getattr__ = submodule_getattr(__name__)
