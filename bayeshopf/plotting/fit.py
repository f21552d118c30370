"""A fit's figures drawn into the user's own axes, with the fit's labels and units.

``fit.plot.bifurcation(ax=ax)`` draws what ``bayeshopf fit`` writes to
``figures/bifurcation.png``, with the names and units the fit already knows
(μ's name and unit, the amplitude's channel and unit), so a user composing a
figure of their own does not repeat them.
"""

from __future__ import annotations

import numpy as np

from bayeshopf.diagnostics.summaries import CI
from bayeshopf.plotting._units import readable_length

__all__ = ["FitPlots"]


class FitPlots:
    """The standard figures of one fit; each method returns the Matplotlib figure.

    Args:
        posterior: The fit's :class:`~bayeshopf.posterior.HybridPosterior`.
    """

    def __init__(self, posterior):
        self._post = posterior

    @property
    def amplitude_label(self) -> str:
        """``"peak-to-peak of <first planar channel>"``."""
        return f"peak-to-peak of {self._post.spec.frame.names[0]}"

    def length_unit(self) -> str | None:
        """The one of m, mm, µm in which the largest measured amplitude reads 1–1000."""
        p = self._post
        return readable_length(p.amplitude_units, float(np.max(np.abs(p.features.amplitude))))

    def bifurcation(self, ax=None, *, ci: float = CI, mu=None, zoom: bool = True,
                    truth=None, **kwargs):
        """The bifurcation diagram with its bands and the recordings.

        Drawn by :func:`~bayeshopf.plotting.plot_bifurcation`.

        Args:
            ax: Axes to draw into (a new figure when ``None``).
            ci: Level of the outer bands.
            mu: μ grid (default: :func:`~bayeshopf.plotting.diagram_grid`).
            zoom: Add the inset that magnifies the bands where they are thin.
            truth: A planted system whose amplitude curve is overlaid.
            **kwargs: More arguments of :func:`~bayeshopf.plotting.plot_bifurcation`.
        """
        from bayeshopf.plotting import diagram_grid, plot_bifurcation

        p = self._post
        mu = diagram_grid(p) if mu is None else np.asarray(mu, float)
        amp_truth = None if truth is None else (lambda m, branch: truth.amplitude(m, branch))
        args = dict(mu_label=p.mu_label, mu_units=p.mu_units, amplitude_units=p.amplitude_units,
                    amplitude_label=self.amplitude_label, truth=amp_truth,
                    zoom="auto" if zoom else None,
                    length_unit=self.length_unit(), ax=ax)
        args.update(kwargs)
        return plot_bifurcation(p.diagram(mu, ci), p.ppc(ci), **args)

    def ppc(self, ax=None, *, ci: float = CI):
        """The predictive check of the recordings (:func:`~bayeshopf.plotting.plot_ppc`)."""
        from bayeshopf.plotting import plot_ppc

        p = self._post
        return plot_ppc(p.ppc(ci), amplitude_units=p.amplitude_units,
                        channels=tuple(p.spec.frame.names[:2]),
                        amplitude_label=self.amplitude_label, length_unit=self.length_unit(),
                        ax=ax)

    def frequency(self, ax=None, *, ci: float = CI, mu=None):
        """Frequency against μ with its bands and the recordings' (``plot_frequency``).

        Raises:
            FitError: For a fit without the frequency model.
        """
        from bayeshopf.errors import FitError
        from bayeshopf.plotting import diagram_grid, plot_frequency

        p = self._post
        if not p.has_frequency:
            raise FitError("this fit has no frequency model (fitted with frequency=False)")
        mu = diagram_grid(p) if mu is None else np.asarray(mu, float)
        branches = ("stable", "unstable") if p.criticality == "subcritical" else ("stable",)
        bands = [p.frequency_band(mu, b, ci=ci) for b in branches]
        pred = [p.frequency_band(mu, b, predictive=True, ci=ci) for b in branches]
        f = p.features
        measured = [(m, hz, "unstable" if u else "stable", se / (2 * np.pi))
                    for m, hz, u, se in zip(f.mu, f.frequency_hz, f.unstable, f.omega_se,
                                            strict=True)]
        return plot_frequency(bands, measured, predictive=pred, mu_label=p.mu_label,
                              mu_units=p.mu_units, ci=ci, ax=ax)

    def time_series(self, recordings, ax=None, *, ci: float = CI, offsets: str = "remove"):
        """Measured against predicted records of each recording (``plot_time_series``).

        Args:
            recordings: The recordings fitted, in the fit's order.
            ax: Axes (one per recording) or ``None``.
            ci: Level of the bands.
            offsets: ``"remove"`` or ``"keep"`` each recording's mean.
        """
        from bayeshopf.plotting import plot_time_series

        p = self._post
        return plot_time_series(p.time_series_bands(recordings, ci=ci), mu_label=p.mu_label,
                                mu_units=p.mu_units, offsets=offsets, ci=ci,
                                length_unit=self.length_unit(), ax=ax)
