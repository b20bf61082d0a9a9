"""Export the pose network to one self-describing ONNX file (fixed point count and crop size).

* legacy TorchScript exporter (``dynamo=False``), opset 17, a single file (no external data);
* inputs named by :func:`spacepose.pose_inputs.pose_input_names`, outputs ``seg_logits``,
  ``kp_offsets``, ``ctr_offsets`` (offsets in metres, ``offset = keypoint - point``);
* no ``ScatterND`` / ``GridSample`` in the graph (export fails otherwise);
* the metadata contract (:func:`pose_metadata`) under ``"spacepose"``: kind, every
  :class:`~spacepose.pose_inputs.PoseInputSpec` field, n_keypoints, keypoints, centre, target,
  net config, dataset seed / size, training commit; the runtime checks it against bundle.json;
* parity: torch eager vs onnxruntime on inputs built by the numpy preprocessing, max |Δ| over the
  three outputs (must be < 1e-4);
* :func:`write_pose_manifest` writes the pose side of ``bundle.json`` (target keypoints, centre,
  radius, bbox; the ``pose`` section) — merged into an existing manifest, never touching the
  stereo side.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
from torch import nn

from spacepose.errors import SpaceposeError
from spacepose.export.metadata import SCHEMA_VERSION, provenance, with_extra
from spacepose.export.onnx_common import (FORBIDDEN_OPS, OPSET, check_overwrite, enforce_parity, export_onnx_file,
                                          max_abs_diff, merge_manifest_section, update_manifest)
from spacepose.models.pose_config import PoseNetConfig
from spacepose.onnx_session import make_session
from spacepose.pose_inputs import PoseInputSpec, build_pose_inputs, pose_input_names

log = logging.getLogger(__name__)

__all__ = ["OPSET", "FORBIDDEN_OPS", "OUTPUT_NAMES", "pose_metadata", "example_feeds", "export_pose", "parity_check",
           "export_checkpoint", "write_pose_manifest", "target_geometry"]

OUTPUT_NAMES = ("seg_logits", "kp_offsets", "ctr_offsets")


def pose_metadata(net_config: PoseNetConfig, *, keypoints: np.ndarray, centre: np.ndarray, target: str,
                  dataset: Mapping[str, Any] | None = None, training_commit: str | None = None,
                  metrics: Mapping[str, Any] | None = None, extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The contract dict of a pose graph (the keys :mod:`spacepose.bundle` cross-checks included)."""
    spec = net_config.input_spec()
    kps = np.asarray(keypoints, dtype=np.float64).reshape(-1, 3)
    if kps.shape[0] != net_config.n_keypoints:
        raise SpaceposeError(f"{kps.shape[0]} keypoints given, the net predicts {net_config.n_keypoints}")
    n, cw, ch = spec.n_points, spec.crop_size[0], spec.crop_size[1]
    inputs: dict[str, list[int]] = {"rgb": [1, 3, ch, cw], "points": [1, n, spec.point_channels], "choose": [1, n]}
    sizes = spec.level_sizes
    for lv in range(spec.n_levels):
        inputs[f"nbr_{lv}"] = [1, sizes[lv], spec.k]
    for lv in range(spec.n_levels):
        inputs[f"sub_{lv}"] = [1, sizes[lv + 1]]
    for lv in range(spec.n_levels):
        inputs[f"up_{lv}"] = [1, sizes[lv]]
    for lv, stride in enumerate(spec.fusion_strides):
        inputs[f"pix2pt_{lv}"] = [1, (ch // stride) * (cw // stride)]
    meta: dict[str, Any] = {
        "schema": SCHEMA_VERSION,
        "kind": "pose",
        "target": str(target),
        **{k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(spec).items()},
        "n_keypoints": int(net_config.n_keypoints),
        "keypoints": kps.tolist(),
        "centre": np.asarray(centre, dtype=np.float64).reshape(3).tolist(),
        "inputs": inputs,
        "outputs": {"seg_logits": [1, n, net_config.n_classes], "kp_offsets": [1, net_config.n_keypoints, n, 3],
                    "ctr_offsets": [1, n, 3]},
        "offset_convention": "offset = keypoint - point (metres, camera frame); vote = point + offset",
        "normalisation": {"rgb": "float32 RGB 0-255, normalised inside the graph",
                          "points": "[(xyz - mean of sampled xyz) / xyz_scale, rgb / 255 (, normals)]"},
        "config": json.loads(json.dumps(dataclasses.asdict(net_config), default=list)),
        **provenance(dataset=dataset, training_commit=training_commit, metrics=metrics),
    }
    return with_extra(meta, extra)


def example_feeds(spec: PoseInputSpec, seed: int = 0, distance_m: float = 20.0) -> dict[str, np.ndarray]:
    """Graph inputs of a synthetic frame (an ellipsoid-ish cloud in front of the camera, random crop)."""
    rng = np.random.default_rng(seed)
    n = spec.n_points
    cw, ch = spec.crop_size
    xyz = rng.normal(0.0, 1.0, size=(n, 3)) * [2.0, 1.2, 0.6] + [0.0, 0.0, distance_m]
    pixels = np.stack([rng.integers(0, cw, n), rng.integers(0, ch, n)], axis=1).astype(np.int64)
    crop = rng.integers(0, 256, size=(ch, cw, 3), dtype=np.uint8)
    feeds, _ = build_pose_inputs(crop, xyz.astype(np.float32), pixels, spec)
    return feeds


def export_pose(model: nn.Module, path: str | os.PathLike, *, metadata: Mapping[str, Any], force: bool = False,
                opset: int = OPSET) -> Path:
    """Export ``model`` (a :class:`~spacepose.models.pose_net.PoseNet`) into one ONNX file with ``metadata``.

    Raises:
        SpaceposeError: ``path`` exists and ``force`` is False, or the graph holds a forbidden op.
    """
    out = check_overwrite(path, force)
    model = model.eval()
    spec = model.cfg.input_spec()
    feeds = example_feeds(spec)
    names = pose_input_names(spec.n_levels)
    args = tuple(torch.from_numpy(feeds[n]) for n in names)
    proto = export_onnx_file(model, args, out, input_names=names, output_names=OUTPUT_NAMES, metadata=metadata,
                             opset=opset, graph_name="pose graph")
    log.info("exported %s (%d points, crop %s, %d nodes)", out, spec.n_points, spec.crop_size, len(proto.graph.node))
    return out


def parity_check(model: nn.Module, onnx_path: str | os.PathLike, *, seed: int = 1, threads: int = 2) -> dict[str, float]:
    """max |torch eager - onnxruntime| per output (and ``"max"``) on :func:`example_feeds`."""
    spec = model.cfg.input_spec()
    feeds = example_feeds(spec, seed=seed)
    names = pose_input_names(spec.n_levels)
    with torch.no_grad():
        ref = model.eval()(*[torch.from_numpy(feeds[n]) for n in names])
    session = make_session(onnx_path, threads=threads)
    got = session.run(list(OUTPUT_NAMES), feeds)
    diffs = {}
    for name, r, g in zip(OUTPUT_NAMES, ref, got):
        diffs[name] = max_abs_diff(name, g, r.numpy())
    diffs["max"] = max(diffs.values())
    return diffs


def target_geometry(target: str, centre: np.ndarray, n_surface: int = 6000, seed: int = 0,
                    n_silhouette: int = 0) -> dict[str, Any]:
    """``mesh_scale``, ``radius`` (about ``centre``), ``bbox_min``/``bbox_max`` and ``n_surface``
    area-uniform ``surface_points`` with their faces' unit ``surface_normals`` (seeded; for the
    runtime's surface checks, ICP and :mod:`spacepose.registration`) of a shipped target mesh.
    With ``n_silhouette`` > 0 also that many more area-uniform ``silhouette_points`` (seed
    ``seed + 1``), whose splat is the target's outline in :mod:`spacepose.silhouette`."""
    import trimesh

    from spacepose.tools.targets import load_target

    tg = load_target(target)
    verts = np.asarray(tg.mesh.vertices, dtype=np.float64)
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    radius = float(np.max(np.linalg.norm(verts - np.asarray(centre, dtype=np.float64), axis=1)))
    surface, faces = trimesh.sample.sample_surface(tg.mesh, int(n_surface), seed=int(seed))
    normals = np.asarray(tg.mesh.face_normals, dtype=np.float64)[faces]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    out = {"mesh_scale": float(tg.scale), "radius": radius, "bbox_min": lo.tolist(), "bbox_max": hi.tolist(),
           "surface_points": np.round(np.asarray(surface, dtype=np.float64), 4).tolist(),
           "surface_normals": np.round(normals, 5).tolist()}
    if n_silhouette > 0:
        outline, _ = trimesh.sample.sample_surface(tg.mesh, int(n_silhouette), seed=int(seed) + 1)
        out["silhouette_points"] = np.round(np.asarray(outline, dtype=np.float64), 3).tolist()
    return out


def write_pose_manifest(bundle_dir: str | os.PathLike, *, net_config: PoseNetConfig, keypoints: np.ndarray,
                        centre: np.ndarray, target: str, pose_file: str = "pose.onnx",
                        geometry: Mapping[str, Any] | None = None, distance_range_m: tuple[float, float] | None = None,
                        dataset: Mapping[str, Any] | None = None, training_commit: str | None = None,
                        metrics: Mapping[str, Any] | None = None) -> Path:
    """Write the pose side of ``bundle_dir/bundle.json`` (atomic; other sections are kept).

    Sets ``target`` (name, keypoints, centre, plus ``geometry``: mesh_scale, radius, bbox),
    ``pose`` (file, n_keypoints, input spec, offset_sign 1) and, when given, ``distance_range_m``,
    ``dataset``, ``training_commit`` and ``metrics.pose``. A manifest that did not exist holds only
    these sections (+ schema) until the stereo export adds its own.
    """
    def update(data: dict[str, Any]) -> None:
        tgt = dict(data.get("target") or {})
        if tgt.get("name") not in (None, target):
            log.warning("bundle.json target %r replaced by %r", tgt.get("name"), target)
            tgt = {}
        tgt.update({"name": target, "keypoints": np.asarray(keypoints, dtype=np.float64).tolist(),
                    "centre": np.asarray(centre, dtype=np.float64).reshape(3).tolist()})
        tgt.update(dict(geometry or {}))
        data["target"] = tgt
        spec = net_config.input_spec()
        pose = {"file": pose_file, "n_keypoints": int(net_config.n_keypoints), "offset_sign": 1}
        pose.update({k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(spec).items()})
        data["pose"] = pose
        if distance_range_m is not None:
            data["distance_range_m"] = [float(distance_range_m[0]), float(distance_range_m[1])]
        merge_manifest_section(data, "dataset", dataset)
        if training_commit is not None:
            data["training_commit"] = training_commit
        merge_manifest_section(data, "metrics", metrics, sub="pose")

    return update_manifest(bundle_dir, update)


def export_checkpoint(ckpt_path: str | os.PathLike, out: str | os.PathLike, *, force: bool = False,
                      parity: bool = True, tolerance: float = 1e-4, metrics: Mapping[str, Any] | None = None,
                      update_manifest: bool = True, geometry: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Export a pose training checkpoint; returns ``{"path", "parity", "metadata", "manifest"}``.

    ``geometry`` (mesh_scale, radius, bbox) defaults to :func:`target_geometry` of the
    checkpoint's target when the mesh is available.

    Raises:
        SpaceposeError: ``out`` exists without ``force``, or parity >= ``tolerance`` (file removed).
    """
    from spacepose.tools.train_pose import load_checkpoint, model_from_checkpoint

    ckpt = load_checkpoint(ckpt_path)
    model, net_cfg = model_from_checkpoint(ckpt)
    dataset = dict(ckpt.get("dataset", {}))
    train_cfg = ckpt.get("train_config", {})
    meta = pose_metadata(net_cfg, keypoints=np.asarray(ckpt["keypoints"]), centre=np.asarray(ckpt["centre"]),
                         target=str(ckpt.get("target", "tdrs")), dataset=dataset, training_commit=ckpt.get("commit"),
                         metrics=metrics,
                         extra={"training": {"step": ckpt.get("step"), "batch": train_cfg.get("batch"),
                                             "depth_source": train_cfg.get("depth_source"),
                                             "lr": [train_cfg.get("lr_min"), train_cfg.get("lr_max")],
                                             "cycles": train_cfg.get("cycles")}})
    path = export_pose(model, out, metadata=meta, force=force)
    result: dict[str, Any] = {"path": str(path), "metadata": meta, "parity": None, "manifest": None}
    if parity:
        diffs = parity_check(model, path)
        result["parity"] = diffs
        enforce_parity(path, diffs["max"], tolerance)
    if update_manifest:
        if geometry is None:
            try:
                geometry = target_geometry(meta["target"], np.asarray(ckpt["centre"]))
            except Exception as err:  # a custom target without a shipped mesh: leave the geometry alone
                log.warning("target geometry unavailable (%s); bundle.json target radius/bbox not updated", err)
                geometry = {}
        result["manifest"] = str(write_pose_manifest(
            path.parent, net_config=net_cfg, keypoints=np.asarray(ckpt["keypoints"]), centre=np.asarray(ckpt["centre"]),
            target=meta["target"], pose_file=path.name, geometry=geometry,
            distance_range_m=dataset.get("distance_range_m"),
            dataset={"seed": dataset.get("seed"), "size": dataset.get("size")}, training_commit=ckpt.get("commit"),
            metrics=metrics))
    return result
