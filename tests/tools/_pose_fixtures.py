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
