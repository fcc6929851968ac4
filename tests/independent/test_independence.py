"""The generator must share no code with the detector: every module of pipeline.bench.independent
imports only numpy, scipy, pandas, yaml, the standard library and its own package (checked on the ASTs,
so an import hidden in a function counts too)."""

import ast
import sys
from pathlib import Path

import pipeline.bench.independent as pkg

ROOT = Path(pkg.__file__).parent
ALLOWED_THIRD_PARTY = {"numpy", "scipy", "pandas", "yaml"}


def _imports(path: Path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, 0, node.lineno
        elif isinstance(node, ast.ImportFrom):
            yield node.module or "", node.level, node.lineno


def _violations(path: Path) -> list[str]:
    bad = []
    for mod, level, line in _imports(path):
        top = mod.split(".")[0]
        where = f"{path.name}:{line}"
        if level >= 2:                                   # from .. import x: leaves the package
            bad.append(f"{where}: relative import of level {level}")
        elif level == 1:
            continue
        elif top == "pipeline":
            if not (mod == "pipeline.bench.independent" or mod.startswith("pipeline.bench.independent.")):
                bad.append(f"{where}: imports {mod}")
        elif top not in ALLOWED_THIRD_PARTY and top not in sys.stdlib_module_names:
            bad.append(f"{where}: imports {mod} (not numpy/scipy/pandas/yaml/stdlib)")
    return bad


def test_generator_imports_nothing_of_the_detector():
    files = sorted(ROOT.rglob("*.py"))
    assert len(files) >= 6
    bad = [v for f in files for v in _violations(f)]
    assert bad == []


def test_the_scan_catches_a_forbidden_import(tmp_path):
    # the checker itself: each forbidden form is reported, the allowed ones are not
    src = tmp_path / "m.py"
    src.write_text("import numpy\nfrom scipy import integrate\nimport json\nfrom . import signals\n"
                   "def f():\n    from pipeline.model import Model\n    import numba\n"
                   "from .. import synthetic\nfrom pipeline.bench.independent import case\n")
    bad = _violations(src)
    assert len(bad) == 3
    assert any("pipeline.model" in b for b in bad)
    assert any("numba" in b for b in bad)
    assert any("level 2" in b for b in bad)
