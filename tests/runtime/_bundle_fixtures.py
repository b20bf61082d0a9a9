"""A tiny but complete model bundle for plumbing tests (graphs built with onnx.helper, no torch).

* stereo graph: ``disparity = FAKE_DISPARITY * (left red channel > 10)`` — constant disparity (in
  graph pixels) on every bright pixel, 0 elsewhere (dark sky).
* pose graph: every point is target when its red value > 0.2; offsets are built so that every
  vote lands on ``xyz_mean + model point``: ``offset_j = K_j - (xyz - xyz_mean)`` (the graph sees
  ``(xyz - xyz_mean) / xyz_scale``). The fitted pose is therefore exactly ``R = I``,
  ``t = mean of the sampled points`` (object centre at the origin).

Import these helpers from test modules (``from _bundle_fixtures import ...``); they are not
fixtures themselves so that ``conftest.py`` stays free for other helpers.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

FAKE_DISPARITY = 60.0
STEREO_SIZE = (256, 256)
IMAGE_SIZE = (640, 480)

KEYPOINTS = np.array([
    [2.4, 0.0, 0.2], [-2.4, 0.0, 0.2], [0.0, 1.5, 0.0], [0.0, -1.5, 0.0],
    [0.5, 0.5, 1.0], [-0.5, -0.5, -0.3], [1.2, -0.8, 0.6], [-1.0, 1.0, 0.8],
])
CENTRE = np.zeros(3)

POSE_SPEC = dict(n_points=256, k=8, n_levels=2, ratio=4, crop_size=[64, 64], xyz_scale=2.5,
                 use_normals=False, sampling="random", seed=0)


def manifest(**overrides) -> dict:
    """A valid bundle.json dict (tiny graphs, paper rig at 640x480, generous distance range)."""
    data = {
        "schema": "spacepose.bundle/1",
        "target": {"name": "tiny", "mesh_scale": 1.0, "keypoints": KEYPOINTS.tolist(),
                   "centre": CENTRE.tolist(), "radius": 3.0,
                   "bbox_min": [-2.5, -1.55, -0.33], "bbox_max": [2.5, 1.55, 1.03]},
        "stereo": {"file": "stereo.onnx", "input_size": list(STEREO_SIZE), "iters": 1,
                   "normalisation": "rgb_0_255", "max_disp": 192},
        "pose": {"file": "pose.onnx", "n_keypoints": len(KEYPOINTS), **POSE_SPEC},
        "voting": {"min_points": 32},
        "rig": {"image_size": list(IMAGE_SIZE), "focal_px": 800.0, "baseline_m": 1.0},
        "distance_range_m": [2.0, 200.0],
        "dataset": {"seed": 0, "size": 0},
        "training_commit": "test",
        "metrics": {},
    }
    data.update(overrides)
    return data


def _save(model, path: Path, metadata: dict) -> None:
    import onnx

    from spacepose.onnx_session import write_metadata

    write_metadata(model, metadata)
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def _model(graph):
    from onnx import helper

    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    return model


def make_stereo_graph(path: Path, metadata: dict | None = None, size=STEREO_SIZE,
                      disparity: float = FAKE_DISPARITY) -> None:
    from onnx import TensorProto, helper, numpy_helper

    w, h = size
    inits = [numpy_helper.from_array(np.array([0], np.int64), "s0"),
             numpy_helper.from_array(np.array([1], np.int64), "s1"),
             numpy_helper.from_array(np.array([1], np.int64), "ax"),
             numpy_helper.from_array(np.array(10.0, np.float32), "thr"),
             numpy_helper.from_array(np.array(disparity, np.float32), "dval")]
    nodes = [helper.make_node("Slice", ["left", "s0", "s1", "ax"], ["red"]),
             helper.make_node("Greater", ["red", "thr"], ["bright"]),
             helper.make_node("Cast", ["bright"], ["brightf"], to=TensorProto.FLOAT),
             helper.make_node("Mul", ["brightf", "dval"], ["disparity"])]
    graph = helper.make_graph(
        nodes, "tiny_stereo",
        [helper.make_tensor_value_info(n, TensorProto.FLOAT, [1, 3, h, w]) for n in ("left", "right")],
        [helper.make_tensor_value_info("disparity", TensorProto.FLOAT, [1, 1, h, w])], inits)
    meta = {"kind": "stereo", "input_size": [w, h], "iters": 1, "max_disp": 192, "target": "tiny",
            "normalisation": "rgb_0_255"}
    meta.update(metadata or {})
    _save(_model(graph), path, meta)


def make_pose_graph(path: Path, metadata: dict | None = None, keypoints: np.ndarray = KEYPOINTS) -> None:
    from onnx import TensorProto, helper, numpy_helper

    from spacepose.pose_inputs import PoseInputSpec, pose_input_names

    spec = PoseInputSpec(**{**POSE_SPEC, "crop_size": tuple(POSE_SPEC["crop_size"])})
    n, m = spec.n_points, len(keypoints)
    cw, ch = spec.crop_size
    sizes = spec.level_sizes
    inputs = [helper.make_tensor_value_info("rgb", TensorProto.FLOAT, [1, 3, ch, cw]),
              helper.make_tensor_value_info("points", TensorProto.FLOAT, [1, n, spec.point_channels]),
              helper.make_tensor_value_info("choose", TensorProto.INT64, [1, n])]
    for stem in ("nbr", "sub", "up", "pix2pt"):
        for level in range(spec.n_levels):
            shape = {"nbr": [1, sizes[level], spec.k], "sub": [1, sizes[level + 1]], "up": [1, sizes[level]],
                     "pix2pt": [1, (ch // spec.fusion_strides[level]) * (cw // spec.fusion_strides[level])]}[stem]
            inputs.append(helper.make_tensor_value_info(f"{stem}_{level}", TensorProto.INT64, shape))
    assert [i.name for i in inputs] == pose_input_names(spec.n_levels)
    inits = [numpy_helper.from_array(np.array([0], np.int64), "c0"),
             numpy_helper.from_array(np.array([3], np.int64), "c3"),
             numpy_helper.from_array(np.array([4], np.int64), "c4"),
             numpy_helper.from_array(np.array([2], np.int64), "ax2"),
             numpy_helper.from_array(np.array([1], np.int64), "ax1"),
             numpy_helper.from_array(np.array(spec.xyz_scale, np.float32), "scale"),
             numpy_helper.from_array(np.array(0.2, np.float32), "rthr"),
             numpy_helper.from_array(np.array(50.0, np.float32), "gain"),
             numpy_helper.from_array(np.array(0.0, np.float32), "zero"),
             numpy_helper.from_array(keypoints.astype(np.float32).reshape(1, m, 1, 3), "kconst")]
    nodes = [helper.make_node("Slice", ["points", "c0", "c3", "ax2"], ["xyzn"]),
             helper.make_node("Mul", ["xyzn", "scale"], ["rel"]),                  # xyz - mean (m)
             helper.make_node("Neg", ["rel"], ["ctr_offsets"]),                    # centre - point
             helper.make_node("Unsqueeze", ["rel", "ax1"], ["rel4"]),
             helper.make_node("Sub", ["kconst", "rel4"], ["kp_offsets"]),
             helper.make_node("Slice", ["points", "c3", "c4", "ax2"], ["red"]),
             helper.make_node("Sub", ["red", "rthr"], ["red0"]),
             helper.make_node("Mul", ["red0", "gain"], ["logit1"]),
             helper.make_node("Mul", ["red", "zero"], ["logit0"]),
             helper.make_node("Concat", ["logit0", "logit1"], ["seg_logits"], axis=2)]
    outputs = [helper.make_tensor_value_info("seg_logits", TensorProto.FLOAT, [1, n, 2]),
               helper.make_tensor_value_info("kp_offsets", TensorProto.FLOAT, [1, m, n, 3]),
               helper.make_tensor_value_info("ctr_offsets", TensorProto.FLOAT, [1, n, 3])]
    graph = helper.make_graph(nodes, "tiny_pose", inputs, outputs, inits)
    meta = {"kind": "pose", "target": "tiny", "n_keypoints": m, **POSE_SPEC,
            "keypoints": keypoints.tolist(), "centre": CENTRE.tolist()}
    meta.update(metadata or {})
    _save(_model(graph), path, meta)


_CACHE: dict[str, Path] = {}


def make_bundle(folder: Path, manifest_overrides: dict | None = None, stereo_meta: dict | None = None,
                pose_meta: dict | None = None) -> Path:
    """Write a complete tiny bundle into ``folder`` (created) and return it."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    key = "graphs"
    if stereo_meta is None and pose_meta is None and key in _CACHE:
        for name in ("stereo.onnx", "pose.onnx"):
            shutil.copyfile(_CACHE[key] / name, folder / name)
    else:
        make_stereo_graph(folder / "stereo.onnx", stereo_meta)
        make_pose_graph(folder / "pose.onnx", pose_meta)
        if stereo_meta is None and pose_meta is None:
            _CACHE[key] = folder
    (folder / "bundle.json").write_text(json.dumps(manifest(**(manifest_overrides or {})), indent=1))
    (folder / "MODEL_CARD.md").write_text("# tiny test bundle\nPlumbing only; not a trained model.\n")
    return folder


def synthetic_pair(dtype=np.uint8, shift: int = 40, size=IMAGE_SIZE, colour: bool = True):
    """A dark frame with a bright textured rectangle (the "target") in left, shifted left in right."""
    w, h = size
    rng = np.random.default_rng(0)
    left = np.zeros((h, w), np.float64)
    x0, y0, x1, y1 = w // 2 - 60, h // 2 - 40, w // 2 + 60, h // 2 + 40
    left[y0:y1, x0:x1] = 120 + 100 * rng.random((y1 - y0, x1 - x0))
    right = np.zeros_like(left)
    right[y0:y1, x0 - shift:x1 - shift] = left[y0:y1, x0:x1]
    scale = 257.0 if dtype == np.uint16 else 1.0
    left, right = (np.rint(im * scale).astype(dtype) for im in (left, right))
    if colour:
        left, right = (np.repeat(im[..., None], 3, axis=2) for im in (left, right))
    return left, right
