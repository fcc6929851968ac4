"""The demo report in a real headless Chromium at 1400 px: no console error, every figure drawn with a
non-zero size, nothing wider than the viewport; the screenshot is kept as a CI artifact."""

import os
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.report.browser import find_browser, inspect_page

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "reports" / "ci-artifacts"


def _need_browser():
    if find_browser() is None:
        if os.environ.get("CI") or os.environ.get("SYSID_REQUIRE_BROWSER") == "1":
            pytest.fail("Chromium is required in CI (.ci/run installs Debian's chromium)")
        pytest.skip("no Chromium on this machine (apt-get install chromium)")


@pytest.mark.parametrize("config", ["demo.yaml", "course_project.yaml"])
def test_report_in_headless_chromium(tmp_path, config):
    _need_browser()
    assert main(["report", str(ROOT / "configs" / config), "--out", str(tmp_path / "run")]) == 0
    shot = ARTIFACTS / f"report-{Path(config).stem}-1400px.png"
    r = inspect_page(tmp_path / "run" / "report.html", width=1400, screenshot=shot)
    assert r["console_errors"] == []
    assert r["external"] == []
    assert len(r["images"]) >= 8
    for img in r["images"]:
        assert img["complete"] and img["natural"][0] > 0 and img["width"] > 0 and img["height"] > 0, img["alt"]
    assert r["wide"] == [], r["wide"][:5]
    assert r["scrollWidth"] <= r["viewport"] == 1400
    for sec in ("summary", "data", "simulation", "residuals", "findings", "models", "uncertainty", "provenance"):
        assert sec in r["sections"]
    assert shot.is_file() and shot.stat().st_size > 10_000
