"""The wheel ships every subpackage and the models (checked from pyproject.toml, no build)."""

import fnmatch
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_subpackage_and_model_file_is_shipped():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    packages = set(config["packages"])
    on_disk = {
        ".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "sustain_drake").rglob("__init__.py")
    }
    assert on_disk <= packages, f"not shipped: {sorted(on_disk - packages)}"
    assert config["package-dir"]["sustain_drake.models"] == "models"
    globs = config["package-data"]["sustain_drake.models"]
    model_files = [
        p.relative_to(ROOT / "models").as_posix()
        for p in (ROOT / "models").rglob("*")
        if p.is_file() and p.suffix != ".py" and "__pycache__" not in p.parts
    ]
    missing = [f for f in model_files if not any(fnmatch.fnmatch(f, g) for g in globs)]
    assert not missing, f"model files not in package-data: {missing}"
    assert "package.xml" in model_files
