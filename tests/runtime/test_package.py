"""The flight package's import hygiene: no torch (or other training-side module) on import."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

RUNTIME = Path(__file__).resolve().parents[2] / "runtime"
TRAINING_ONLY = ("torch", "scipy", "sklearn", "trimesh", "open3d", "matplotlib", "onnx.helper")


def _loaded_after(code: str) -> set[str]:
    probe = code + "\nimport sys, json\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_every_runtime_module_imports_without_training_dependencies():
    names = sorted(p.stem for p in RUNTIME.glob("*.py") if p.stem != "__init__")
    assert "estimator" in names and "cli" in names
    loaded = _loaded_after("import spacepose\n" + "\n".join(f"import spacepose.{n}" for n in names)
                           + "\nimport spacepose.calibration")
    bad = sorted(m for m in loaded if m.split(".")[0] in TRAINING_ONLY or m in TRAINING_ONLY)
    assert bad == [], f"the flight runtime imported training-side modules: {bad}"


def test_cli_help_lists_every_command_without_torch():
    out = subprocess.run([sys.executable, "-m", "spacepose.cli", "--help"], capture_output=True, text=True,
                         timeout=120, check=True)
    for command in ("estimate", "disparity", "profile", "demo", "calibrate", "render", "train-stereo", "eval-pose"):
        assert command in out.stdout
    loaded = _loaded_after("from spacepose.cli import build_parser\nbuild_parser()")
    assert not any(m.split(".")[0] == "torch" for m in loaded)
