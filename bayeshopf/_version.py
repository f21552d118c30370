"""The package's version, in one place (``bayeshopf.__version__``)."""

__version__ = "0.1.0"
