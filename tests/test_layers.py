"""The package's layers point one way: math -> systems -> loops -> station -> examples -> experiments ->
sweeps -> command line, with the shared helpers at the bottom. Checked on the import graph of the
source itself."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "sustain_drake"

# Bottom to top; a module may import its own layer and the layers below it, never one above.
LAYERS = (
    ("helpers", ("sustain_drake.files", "sustain_drake.provenance")),
    ("math", ("sustain_drake.identification", "sustain_drake.perception", "sustain_drake.recorded_data")),
    ("systems", ("sustain_drake.systems", "sustain_drake.calibration_export")),
    ("loops", ("sustain_drake.loops",)),
    ("station", ("sustain_drake.station",)),
    ("examples", ("sustain_drake.examples",)),
    ("experiments", ("sustain_drake.experiments",)),
    ("sweeps", ("sustain_drake.sweeps",)),
    ("command line", ("sustain_drake.cli",)),
)
MATH = ("sustain_drake.identification", "sustain_drake.perception", "sustain_drake.recorded_data")


def layer_of(module: str) -> int:
    for rank, (_, prefixes) in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return rank
    raise AssertionError(f"{module} is in no layer: add it to LAYERS")


def module_name(path: Path, root: Path = ROOT) -> str:
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path, root: Path = ROOT) -> set[str]:
    """The sustain_drake modules (or names in them) a file imports, absolute or relative, anywhere."""
    here = module_name(path, root)
    package = here if path.name == "__init__.py" else here.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                kept = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(kept + [base]).strip(".")
            found.add(base)
            found |= {f"{base}.{a.name}" for a in node.names}
    return {m for m in found if m.startswith("sustain_drake.")}


def _rank(target: str) -> int:
    try:
        return layer_of(target)
    except AssertionError:
        return layer_of(target.rsplit(".", 1)[0])  # a name imported from a module


def upward_imports(root: Path) -> list[str]:
    """``importer -> target`` for every import from a lower layer to a higher one under ``root``."""
    upward = []
    for path in sorted((root / "sustain_drake").rglob("*.py")):
        importer = module_name(path, root)
        if importer == "sustain_drake":
            continue
        upward += [f"{importer} -> {t}" for t in sorted(imports_of(path, root))
                   if _rank(t) > layer_of(importer)]
    return upward


def test_every_import_points_down():
    assert len(list(PACKAGE.rglob("*.py"))) > 40
    assert upward_imports(ROOT) == []


def test_the_layer_check_sees_an_upward_import(tmp_path):
    """The check is not vacuous: a math module importing a system, or a system importing the station
    relatively, is caught."""
    math_module = tmp_path / "sustain_drake" / "identification" / "bad.py"
    math_module.parent.mkdir(parents=True)
    math_module.write_text("import numpy\nfrom sustain_drake.systems.depth_noise import DepthNoiseModel\n")
    system = tmp_path / "sustain_drake" / "systems" / "bad.py"
    system.parent.mkdir(parents=True)
    system.write_text("from ..station import build\n")
    assert upward_imports(tmp_path) == [
        "sustain_drake.identification.bad -> sustain_drake.systems.depth_noise",
        "sustain_drake.identification.bad -> sustain_drake.systems.depth_noise.DepthNoiseModel",
        "sustain_drake.systems.bad -> sustain_drake.station",
        "sustain_drake.systems.bad -> sustain_drake.station.build"]


def test_benches_use_no_command_line_code():
    """The benches run experiments through ``experiments.run``, as a user's script would."""
    for path in (ROOT / "bench").glob("*.py"):
        found = imports_of(path, ROOT / "bench")
        assert not any(m.startswith("sustain_drake.cli") for m in found), path


def test_benches_import_names_the_package_has():
    """Every name a bench imports from the package exists (a bench is run by hand, rarely: a moved
    function must not break it unnoticed)."""
    missing = []
    for path in sorted((ROOT / "bench").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("sustain_drake"):
                module = importlib.import_module(node.module)
                missing += [f"{path.name}: {node.module}.{a.name}" for a in node.names
                            if not hasattr(module, a.name)
                            and not (hasattr(module, "__path__")  # a package's submodule
                                     and importlib.util.find_spec(f"{node.module}.{a.name}"))]
    assert missing == []


@pytest.mark.parametrize("package", MATH)
def test_the_math_imports_without_pydrake(package):
    """The paper's equations run with numpy, scipy and OpenCV alone: importing every math module
    with pydrake made unimportable succeeds."""
    names = [module_name(p) for p in sorted(PACKAGE.rglob("*.py")) if module_name(p).startswith(package)]
    assert names
    code = (
        "import importlib.abc, sys\n"
        "class Block(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path, target=None):\n"
        "        if name.split('.')[0] in ('pydrake', 'drake'):\n"
        "            raise ImportError(f'blocked: {name}')\n"
        "sys.meta_path.insert(0, Block())\n"
        f"for name in {names!r}:\n"
        "    importlib.import_module(name)\n"
        "assert not any(m.split('.')[0] in ('pydrake', 'drake') for m in sys.modules)\n"
        "print('ok', len(sys.modules))\n"
    )
    result = subprocess.run([sys.executable, "-c", "import importlib\n" + code], cwd=ROOT,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.startswith("ok")
