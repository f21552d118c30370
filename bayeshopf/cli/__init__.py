"""The ``bayeshopf`` command line: ``demo``, ``fit`` and ``predict``."""
