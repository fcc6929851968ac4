"""Silverbox report size and trace visibility (real data), and the opt-in emcee posterior."""

import base64
import io
import os
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from pipeline.cli import main

ROOT = Path(__file__).resolve().parents[2]
SILVERBOX = ROOT.parent / "shared" / "datasets" / "silverbox" / "SNLS80mV.csv"


def _realdata():
    if not SILVERBOX.exists():
        if os.environ.get("SYSID_REQUIRE_REALDATA") == "1":
            pytest.fail(f"{SILVERBOX} is required (SYSID_REQUIRE_REALDATA=1)")
        pytest.skip("../shared/datasets not present")


@pytest.mark.realdata
def test_silverbox_report_is_small_and_shows_the_measured_trace(tmp_path):
    _realdata()
    from PIL import Image
    assert main(["report", str(ROOT / "configs" / "silverbox.yaml"), "--out", str(tmp_path / "sb")]) == 0
    html_path = tmp_path / "sb" / "report.html"
    assert html_path.stat().st_size < 5 * 1024 * 1024
    html = html_path.read_text(encoding="utf-8")
    first = re.search(r'<img alt="measured vs nominal and final model[^"]*" src="data:image/png;base64,([^"]+)"', html)
    im = np.asarray(Image.open(io.BytesIO(base64.b64decode(first.group(1)))).convert("RGB")).astype(int)
    # the 40 400-sample measurement is drawn as a grey min/max envelope over the model outlines,
    # and in black at full resolution in the zoom panel: both must cover a visible part of the figure
    # grey 0.55 at alpha 0.8 over white ≈ (163, 163, 163); over a model outline slightly darker
    neutral = (np.abs(im[..., 0] - im[..., 1]) <= 4) & (np.abs(im[..., 1] - im[..., 2]) <= 4)
    grey = (neutral & (im[..., 0] >= 120) & (im[..., 0] <= 200)).mean()
    black = np.all(im <= 40, axis=2)
    right = black[:, im.shape[1] * 2 // 3:].mean()
    assert grey > 0.01, grey
    assert right > 0.003, right
    assert "min/max envelope" in html


def test_mcmc_posterior_is_overlaid_and_agrees_with_gauss_on_a_near_linear_model(tmp_path):
    """On the demo's final model (nearly linear in its parameters near the optimum, 2100 samples), the
    posterior should match the Laplace/Gauss approximation (Bernstein–von Mises): means within 1 σ,
    sds within a factor 2."""
    cfg = yaml.safe_load((ROOT / "configs" / "demo.yaml").read_text())
    cfg["data"]["path"] = str(ROOT / "data" / "demo.csv")
    cfg["uncertainty"] = "mcmc"
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["report", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "run")]) == 0
    html = (tmp_path / "run" / "report.html").read_text(encoding="utf-8")
    assert "emcee posterior" in html and "posterior draws (orange)" in html
    rows = re.findall(r"<tr><td>(c|k|cubic_stiffness_v_x)</td><td class=\"n\">([-\d.e]+)</td><td class=\"n\">([-\d.e]+)</td>"
                      r"<td class=\"n\">[^<]* to [^<]*</td>\s*"          # the 95 % interval
                      r"<td class=\"n\">([-\d.e]+)</td><td class=\"n\">([-\d.e]+)</td>", html)
    assert len(rows) == 3
    for name, est, sd, pmean, psd in rows:
        est, sd, pmean, psd = map(float, (est, sd, pmean, psd))
        assert abs(pmean - est) < sd, name
        assert 0.5 < psd / sd < 2.0, name
