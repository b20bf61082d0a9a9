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


#: the device machine receives the working tree (tracked files) in at most 64 MiB, with what a job
#: carries on top (see the model card's "Training on a lent accelerator": 15 MB of wheels); keep room
TREE_LIMIT_BYTES = 48 * 2**20


def test_tracked_files_fit_the_device_transfer():
    import shutil

    import pytest

    root = RUNTIME.parent
    if shutil.which("git") is None or not (root / ".git").exists():
        pytest.skip("not a git checkout")
    out = subprocess.run(["git", "ls-files", "-z"], cwd=root, capture_output=True, check=True, timeout=60).stdout
    files = [root / name for name in out.decode().split("\0") if name]
    total = sum(f.stat().st_size for f in files if f.is_file())
    biggest = sorted(((f.stat().st_size, f.relative_to(root)) for f in files if f.is_file()), reverse=True)[:5]
    assert total <= TREE_LIMIT_BYTES, f"tracked files take {total / 2**20:.1f} MiB; the biggest: {biggest}"
