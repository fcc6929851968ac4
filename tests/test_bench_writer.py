"""`python -m pipeline.bench` rewrites the sections it runs; a section's hand-written notes (below
its NOTES line) and every other section survive, with --only and in a full run."""

from __future__ import annotations

import sys
import types

import pipeline.bench.__main__ as bm
from pipeline.bench.diagnosis import END, START

OLD = f"""# Benchmarks

Machine: old.

## Sec: the first

| old table |

{bm.NOTES}

History paragraph written by hand.

## Other: untouched

other text

{START}
diagnosis block
{END}

### Held-out seeds, written below the block

held-out table

## Last: generated

last text
"""


def _fake_section(monkeypatch, text):
    mod = types.ModuleType("benchfake.sec")
    mod.run = lambda quick=False: text
    monkeypatch.setitem(sys.modules, "benchfake.sec", mod)
    monkeypatch.setattr(bm, "SECTIONS", ["benchfake.sec"])


def test_only_keeps_the_sections_notes_and_the_other_sections(tmp_path, monkeypatch):
    out = tmp_path / "B.md"
    out.write_text(OLD)
    _fake_section(monkeypatch, "## Sec: the first\n\n| new table |\n")
    assert bm.main(["--only", "sec", "--out", str(out)]) == 0
    text = out.read_text()
    assert "| new table |" in text and "| old table |" not in text
    assert text.index("| new table |") < text.index("History paragraph written by hand.") < text.index("## Other")
    assert text.count(bm.NOTES) == 1
    assert "other text" in text and "diagnosis block" in text


def test_a_full_run_keeps_the_notes_too(tmp_path, monkeypatch):
    out = tmp_path / "B.md"
    out.write_text(OLD)
    _fake_section(monkeypatch, "## Sec: the first\n\n| new table |\n")
    assert bm.main(["--out", str(out)]) == 0
    text = out.read_text()
    assert "| new table |" in text and "History paragraph written by hand." in text
    assert "diagnosis block" in text and "held-out table" in text


def test_a_section_without_notes_is_replaced_whole(tmp_path, monkeypatch):
    out = tmp_path / "B.md"
    out.write_text(OLD.replace(bm.NOTES + "\n\nHistory paragraph written by hand.\n", ""))
    _fake_section(monkeypatch, "## Sec: the first\n\n| new table |\n")
    assert bm.main(["--only", "sec", "--out", str(out)]) == 0
    text = out.read_text()
    assert "| new table |" in text and bm.NOTES not in text and "| old table |" not in text


def test_two_cause_bench_rewrites_only_its_own_section(tmp_path):
    """The two-cause bench's table goes between its own markers; the diagnosis block and the rest stay;
    a record counts as right only when both causes' families are named."""
    from pipeline.bench import two_causes as tc
    path = tmp_path / "B.md"
    path.write_text(OLD)
    rows = [{"combo": "deadzone+offset", "seed": 1, "verdict": "discrepancy", "findings": ["offset", "dead_zone"],
             "look_ahead": True, "right": True, "seconds": 1.0},
            {"combo": "deadzone+offset", "seed": 2, "verdict": "unexplained_discrepancy", "findings": [],
             "look_ahead": False, "right": False, "seconds": 1.0}]
    for _ in range(2):          # appended once, then replaced in place
        tc.write_section(path, tc.render(rows, (1, 2), 3.0), tc.START, tc.END)
    text = path.read_text()
    assert text.count(tc.START) == 1 and text.startswith(OLD.rstrip())
    assert "**Both named: 1/2.**" in text
    assert "| deadzone+offset | 1/2 | ✓ offset, dead_zone (look-ahead); ✗ unexplained_discrepancy |" in text


def test_two_cause_bench_refuses_bad_options_before_running(tmp_path, capsys):
    import pytest
    from pipeline.bench import two_causes as tc
    for argv, says in ((["--seeds", "x"], "--seeds: expected comma-separated integers"),
                       (["--workers", "0"], "--workers: expected a positive integer"),
                       (["--out", str(tmp_path / "missing" / "B.md")], "--out: the folder of")):
        with pytest.raises(SystemExit) as e:
            tc.main(argv)
        assert e.value.code == 2 and says in capsys.readouterr().err
