"""One self-contained HTML page of a saved fit, to mail or archive.

:func:`write_lab_report` reads a fit folder (:func:`bayeshopf.load_fit`) and
writes a single ``.html`` file that needs nothing else to be read: the figures
as inline SVG, the Hopf and fold points with their intervals, every
recording's measured and predicted amplitude, the checks with their status and
warnings, the settings and seed, and the versions of bayeshopf that made the
fit and the page. No script, style sheet or font is fetched from anywhere.
"""

from __future__ import annotations

import datetime
import html
import io
import json
import os
from pathlib import Path

import numpy as np

from bayeshopf._atomic import replacing
from bayeshopf._format import format_number, interval_text
from bayeshopf._version import __version__
from bayeshopf.diagnostics.summaries import CI
from bayeshopf.errors import OutputError
from bayeshopf.fit_folder import SUMMARY

__all__ = ["lab_report_html", "write_lab_report"]

#: The page's style, inline (no file is fetched).
_STYLE = """
body { font-family: system-ui, sans-serif; max-width: 60rem; margin: 2rem auto; color: #222; }
h1 { font-size: 1.6rem; } h2 { font-size: 1.2rem; margin-top: 2rem; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.5rem 0; }
th, td { padding: 0.2rem 0.7rem; border-bottom: 1px solid #eee; text-align: left; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.ok { color: #176b1b; font-weight: 600; } .warning { color: #a8420a; font-weight: 600; }
figure { margin: 1.5rem 0; } figure svg { max-width: 100%; height: auto; }
figcaption { font-weight: 600; margin-bottom: 0.3rem; }
pre { background: #f6f6f6; padding: 0.6rem; overflow-x: auto; }
"""


def _svg(fig) -> str:
    """A Matplotlib figure as an inline ``<svg>`` element (the figure is closed)."""
    import matplotlib.pyplot as plt

    buf = io.StringIO()
    fig.savefig(buf, format="svg", bbox_inches="tight")
    plt.close(fig)
    text = buf.getvalue()
    return text[text.index("<svg"):]


def _table(header: list[str], rows: list[list[str]], numeric: set[int] = frozenset()) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join(
        "<tr>" + "".join(f'<td class="num">{c}</td>' if j in numeric else f"<td>{c}</td>"
                         for j, c in enumerate(row)) + "</tr>"
        for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _interval_cell(iv) -> str:
    return "—" if iv is None else html.escape(interval_text(iv.median, iv.lo, iv.hi))


def lab_report_html(fit, recordings=None, *, ci: float = CI, title: str | None = None) -> str:
    """The page of :func:`write_lab_report` as a string.

    Args:
        fit: A :class:`~bayeshopf.hybrid.Fit` (fitted or read back).
        recordings: The recordings fitted, for the time-series figure, or ``None``.
        ci: Mass of the intervals and bands.
        title: The page's title (default: the fit folder's name).
    """
    import matplotlib

    matplotlib.use("Agg")
    post = fit.posterior
    name = title or (fit.folder.name if fit.folder is not None else "bayeshopf fit")
    mu_u = html.escape(post.mu_units)
    parts = [f"<h1>{html.escape(name)}</h1>",
             f"<p>Bayesian hybrid normal-form model of a Hopf bifurcation: "
             f"{html.escape(post.criticality)}, {post.features.n_recordings} recordings, "
             f"{html.escape(post.mu_label)} in {mu_u or 'its own units'}. Intervals are "
             f"{100 * ci:g}% equal-tailed posterior intervals.</p>"]

    rows = []
    for key, label in (("mu0", "Hopf point μ0"), ("mu_fold", "fold"), ("a2", "a2"),
                       ("w_unfold", "unfolding curvature w")):
        iv = fit.interval(key, ci)
        if iv is not None:
            unit = mu_u if key in ("mu0", "mu_fold") else ""
            rows.append([html.escape(label), _interval_cell(iv), unit])
    parts += ["<h2>Bifurcation points</h2>",
              _table(["quantity", f"median [{100 * ci:g}% interval]", "unit"], rows, {1})]

    d = fit.diagnostics
    checks = [[html.escape(c.name), f'<span class="{c.status.value}">{c.status.value}</span>']
              for c in d.checks]
    warn = "".join(f"<li>{html.escape(w)}</li>" for w in d.warnings)
    parts += ["<h2>Checks</h2>", _table(["check", "status"], checks),
              f"<ul>{warn}</ul>" if warn else "<p>No warnings: every check passed.</p>"]

    plots = fit.plot
    figures = [("Bifurcation diagram", plots.bifurcation(ci=ci)),
               ("Predictive check of the recordings", plots.ppc(ci=ci))]
    if post.has_frequency:
        figures.append(("Frequency", plots.frequency(ci=ci)))
    if recordings is not None:
        figures.append(("Time series", plots.time_series(recordings, ci=ci)))
    parts.append("<h2>Figures</h2>")
    # the caption above its figure, so that it is not read as the next one's heading
    parts += [f"<figure><figcaption>{html.escape(cap)}</figcaption>{_svg(fig)}</figure>"
              for cap, fig in figures]

    ppc = post.ppc(ci)
    f = post.features
    amp_u = html.escape(post.amplitude_units)
    rec_rows = []
    for i, rec_name in enumerate(f.names):
        p = ppc.predictive[i]
        rec_rows.append([html.escape(rec_name), format_number(float(f.mu[i])),
                         "unstable" if f.unstable[i] else "stable",
                         format_number(float(f.amplitude[i])), _interval_cell(p),
                         "yes" if ppc.covered[i] else "<b>no</b>", str(int(f.n_segments[i])),
                         format_number(float(f.frequency_hz[i]))])
    parts += ["<h2>Recordings</h2>",
              _table(["recording", f"μ ({mu_u})", "branch", f"measured amplitude ({amp_u})",
                      f"predicted ({amp_u})", "inside", "segments", "frequency (Hz)"],
                     rec_rows, {1, 3, 4, 6, 7})]

    settings = dict(post.settings.__dict__)
    made_with = None
    if fit.folder is not None and (fit.folder / SUMMARY).is_file():
        made_with = json.loads((fit.folder / SUMMARY).read_text()).get("bayeshopf_version")
    parts += ["<h2>Settings and provenance</h2>",
              f"<p>Seed {post.seed}; {np.shape(post.samples['mu0'])[0]} posterior draws "
              f"({html.escape(post.run.method)}). Page made by bayeshopf {__version__} on "
              f"{datetime.date.today().isoformat()}"
              + (f"; fit folder <code>{html.escape(str(fit.folder))}</code>"
                 if fit.folder is not None else "")
              + (f"; fitted with bayeshopf {html.escape(str(made_with))}" if made_with else "")
              + ".</p>",
              f"<pre>{html.escape(json.dumps(settings, indent=2, default=str))}</pre>"]
    body = "\n".join(parts)
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f"<title>{html.escape(name)}</title><style>{_STYLE}</style></head>"
            f"<body>\n{body}\n</body></html>\n")


def write_lab_report(fit, out: str | os.PathLike[str], recordings=None, *,
                     ci: float = CI) -> Path:
    """Write :func:`lab_report_html` to ``out`` atomically.

    Args:
        fit: A :class:`~bayeshopf.hybrid.Fit`, or a fit folder to read.
        out: The ``.html`` file to write.
        recordings: The recordings fitted, for the time-series figure, or ``None``.
        ci: Mass of the intervals and bands.

    Returns:
        The path written.

    Raises:
        DataError: When ``fit`` is a folder that cannot be read.
        OutputError: When ``out`` cannot be written.
    """
    if isinstance(fit, (str, os.PathLike)):
        from bayeshopf.hybrid import load_fit

        fit = load_fit(fit)
    text = lab_report_html(fit, recordings, ci=ci)
    out = Path(out)
    try:
        with replacing(out) as tmp:
            tmp.write_text(text, encoding="utf-8")
    except OSError as e:
        raise OutputError(f"{out}: cannot write the report ({e.strerror or e})") from None
    return out
