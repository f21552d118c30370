"""The ``bayeshopf`` command line: :mod:`bayeshopf.cli.main` dispatches to one module per command.

``demo``, ``fit``, ``predict``, ``download``, ``plot``, ``simulate``, ``discrepancy``
and ``next`` (:mod:`bayeshopf.cli.design`); what they share lives in the private
modules (``_format``: numbers; ``_schema``: the JSON output; ``_checks``: values
checked and worded with their flags; ``_hybrid`` and ``_summary``: ``fit`` and ``demo``).
"""
