"""The lab report: one self-contained HTML page of a fit, looked at in a real browser."""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pytest

from bayeshopf.hybrid import Fit
from bayeshopf.lab_report import write_lab_report


@pytest.fixture(scope="module")
def page(fast_demo_fit, tmp_path_factory):
    post, rs, _ = fast_demo_fit
    fit = Fit(post)
    out = write_lab_report(fit, tmp_path_factory.mktemp("report") / "fit.html", rs)
    return fit, out, out.read_text(encoding="utf-8")


def test_the_page_fetches_nothing(page):
    _, _, text = page
    assert "<script" not in text and "<link" not in text and "@import" not in text
    # SVG namespaces name the format; no element loads anything from anywhere
    assert not re.search(r'(src|href)="(https?:|//|file:)', text)
    assert text.count("<svg") >= 3            # diagram, predictive check, time series


def test_the_page_holds_the_fits_numbers(page):
    fit, _, text = page
    iv = fit.interval("mu0")
    assert f"{iv.median:.3f}"[:5] in text
    for name in fit.features.names:
        assert name in text
    for w in fit.diagnostics.warnings:
        assert w.replace("&", "&amp;").replace("<", "&lt;")[:40] in text
    assert "Seed 0" in text


def _browser() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.skipif(_browser() is None, reason="Debian's chromium is not installed")
def test_a_real_browser_renders_the_page(page, tmp_path):
    import matplotlib.image as mpimg

    _, out, _ = page
    shot = tmp_path / "shot.png"
    subprocess.run([_browser(), "--headless", "--no-sandbox", "--disable-gpu",
                    "--hide-scrollbars", f"--screenshot={shot}", "--window-size=1000,2400",
                    out.resolve().as_uri()], check=True, capture_output=True, timeout=120)
    img = mpimg.imread(shot)[..., :3]
    ink = img.mean(axis=-1) < 0.9                # anything not near-white
    rows = ink.any(axis=1)
    # text and figures reach far down the page, not a blank or error page
    assert ink.mean() > 0.01
    assert np.flatnonzero(rows).max() > 0.6 * img.shape[0]
    # the figures' colours are drawn (the bands are blue and red, the text is grey)
    coloured = (np.ptp(img, axis=-1) > 0.25).mean()
    assert coloured > 0.002


def test_the_command_writes_the_page_and_refuses_a_missing_folder(page, tmp_path, capsys):
    from bayeshopf.cli.main import main

    fit, _, _ = page
    folder = fit.save(tmp_path / "fit", figures=False).folder
    assert main(["report", str(folder), "--ci", "0.8"]) == 0
    text = (folder / "report.html").read_text(encoding="utf-8")
    assert "<svg" in text and "80% equal-tailed" in text
    assert "fitted with bayeshopf" in text          # the version read from the folder
    assert main(["report", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nowhere" in err[0] and "Traceback" not in err[0]
