"""A tiny rendered tdrs dataset and a tiny pose-net config shared by the pose tool tests.

Import from test modules (``sys.path`` insert + ``from _pose_fixtures import ...``); the dataset is
rendered once per pytest process (8 frames at 160x120, target 10-20 m: a few hundred to a few
thousand target pixels per frame).
"""

from __future__ import annotations

from pathlib import Path

_CACHE: dict[str, Path] = {}

TINY_NET = dict(crop_size=(64, 64), n_points=128, k=8, n_levels=2, ratio=4, rgb_stem=8, rgb_widths=(16, 16),
                rgb_bottleneck=16, rgb_out=8, point_stem=8, point_widths=(16, 16), point_bottleneck=16, head_width=16)


def pose_dataset(tmp_path_factory) -> Path:
    """Render (once) and return the tiny dataset folder."""
    if "ds" not in _CACHE:
        from spacepose.tools.dataset import RenderConfig, render_dataset

        root = tmp_path_factory.getbasetemp() / "pose_ds"
        render_dataset(root, RenderConfig(count=8, size=(160, 120), seed=3, depth_range=(10.0, 20.0)), workers=1)
        _CACHE["ds"] = root
    return _CACHE["ds"]


def tiny_net_config(**overrides):
    from spacepose.models.pose_config import PoseNetConfig

    return PoseNetConfig(**{**TINY_NET, **overrides})


def train_tiny(dataset: Path, out: Path, steps: int = 2, **overrides) -> Path:
    """A tiny trained checkpoint (``out/last.pt``)."""
    from spacepose.tools.train_pose import TrainPoseConfig, train_pose

    cfg = TrainPoseConfig(dataset=str(dataset), out=str(out), steps=steps, batch=2, net=dict(TINY_NET), log_every=1,
                          val_every=10_000, val_samples=1, workers=0, ckpt_every=10_000, radius_m=2.6,
                          depth_source="gt_noisy", **overrides)
    train_pose(cfg)
    return out / "last.pt"


def make_pose_bundle(folder: Path, ckpt: Path) -> Path:
    """A complete bundle: random 64x64 stereo graph + the exported tiny pose graph + manifest."""
    import json

    from spacepose.export.onnx_pose import export_checkpoint
    from spacepose.export.onnx_stereo import export_random_stereo

    folder.mkdir(parents=True, exist_ok=True)
    export_random_stereo(folder / "stereo.onnx", size=(64, 64), iters=2)
    geometry = {"mesh_scale": 0.0473501498, "radius": 2.6, "bbox_min": [-2.5, -1.55, -0.33], "bbox_max": [2.5, 1.55, 1.03]}
    export_checkpoint(ckpt, folder / "pose.onnx", force=True, geometry=geometry)
    path = folder / "bundle.json"
    data = json.loads(path.read_text())
    data.update({"stereo": {"file": "stereo.onnx", "input_size": [64, 64], "iters": 2, "normalisation": "rgb_0_255",
                            "max_disp": 192},
                 "rig": {"image_size": [160, 120], "focal_px": 200.0, "baseline_m": 1.0},
                 "voting": {"min_points": 16}})
    data.setdefault("distance_range_m", [10.0, 20.0])
    from spacepose.onnx_session import read_metadata

    data["stereo"]["max_disp"] = read_metadata(folder / "stereo.onnx").get("max_disp", 192)
    path.write_text(json.dumps(data, indent=1))
    (folder / "MODEL_CARD.md").write_text("# tiny test bundle\n")
    return folder
