"""Reduced-precision copies of a bundle: int8 (static QDQ, calibrated on real frames) or fp16.

``spacepose quantize BUNDLE --out DIR --precision int8 --calib-data DATASET`` writes a new bundle
folder (the source is never modified) whose ``stereo.onnx`` and ``pose.onnx`` are:

* ``int8`` — onnxruntime static quantization, QDQ format, per-channel int8 weights and uint8
  activations, calibrated (MinMax) on the exact graph inputs the flight pipeline builds for
  ``--calib-frames`` training frames (recorded by running :class:`spacepose.estimator.PoseEstimator`
  on them, so the coarse and the fine stereo windows and the pose inputs are all represented);
* ``fp16`` — weights and activations in float16 with float32 inputs and outputs
  (``onnxruntime.transformers.float16``); smaller files, but x86 CPUs have few fp16 kernels, so
  onnxruntime inserts casts and it is usually slower there (measure with ``spacepose profile``).

A bundle's flip classifier (``flip_classifier``) is copied as it is, float32: it decides flips, and a
quantized decision-maker let a flip through before (model card). Each graph keeps the metadata contract, with a ``precision`` entry added; ``bundle.json`` is copied
unchanged, and the model card is the source's under a header that says how this copy was made and
that the numbers below it are those of the float32 graphs. The accuracy cost is measured with the project's own commands on the new folder
(``spacepose eval-stereo DATASET --bundle DIR``, ``spacepose eval-pose DATASET --bundle DIR``).
"""

from __future__ import annotations

import json
import logging
import shutil
import tempfile
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spacepose.errors import SpaceposeError
from spacepose.onnx_session import METADATA_KEY

log = logging.getLogger(__name__)

__all__ = ["PRECISIONS", "record_calibration_feeds", "quantize_int8", "convert_fp16", "quantize_bundle", "winograd_nodes",
           "polyphase_nodes"]

PRECISIONS = ("int8", "fp16")


class _Recorder:
    """Stands in for an onnxruntime session and keeps a copy of every feed it is given."""

    def __init__(self, session: Any, store: list[dict[str, np.ndarray]]) -> None:
        self._session, self._store = session, store

    def run(self, outputs, feeds, *args, **kwargs):
        self._store.append({k: np.array(v, copy=True) for k, v in feeds.items()})
        return self._session.run(outputs, feeds, *args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._session, name)


def record_calibration_feeds(bundle_dir: str | Path, dataset: str | Path, frames: int, split: str = "train",
                             seed: int = 0) -> tuple[list[dict[str, np.ndarray]], list[dict[str, np.ndarray]]]:
    """Graph inputs of the flight pipeline on ``frames`` evenly spaced ``split`` frames -> (stereo, pose) feeds."""
    from spacepose.calibration.rig import load_rig
    from spacepose.estimator import PoseEstimator
    from spacepose.imageio import read_image
    from spacepose.tools.labels import read_labels

    root = Path(dataset)
    recs = read_labels(root, split)
    if not recs:
        raise SpaceposeError(f"{root}: no {split!r} frames to calibrate on")
    picks = [recs[int(i)] for i in np.linspace(0, len(recs) - 1, num=min(frames, len(recs)))]
    est = PoseEstimator(load_rig(root / "rig.yaml"), bundle=bundle_dir, threads=1, use_prior=False, seed=seed)
    stereo_feeds: list[dict[str, np.ndarray]] = []
    pose_feeds: list[dict[str, np.ndarray]] = []
    infer = est.stereo._infer

    def recording_infer(left: np.ndarray, right: np.ndarray) -> np.ndarray:
        stereo_feeds.append({"left": np.array(left, copy=True), "right": np.array(right, copy=True)})
        return infer(left, right)

    est.stereo._infer = recording_infer
    est.pose_session = _Recorder(est.pose_session, pose_feeds)
    for rec in picks:
        est.estimate(read_image(root / "left" / f"{rec.frame}.png"), read_image(root / "right" / f"{rec.frame}.png"))
    log.info("recorded %d stereo and %d pose feeds from %d frames", len(stereo_feeds), len(pose_feeds), len(picks))
    return stereo_feeds, pose_feeds


def _copy_metadata(src: Path, dst: Path, precision: str, extra: dict[str, Any]) -> None:
    import onnx

    meta_src = {p.key: p.value for p in onnx.load(str(src), load_external_data=False).metadata_props}
    model = onnx.load(str(dst))
    contract = json.loads(meta_src[METADATA_KEY])
    contract["precision"] = {"precision": precision, **extra}
    del model.metadata_props[:]
    for key, value in meta_src.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, json.dumps(contract) if key == METADATA_KEY else value
    onnx.save(model, str(dst))


def _constants(model) -> dict[str, np.ndarray]:
    """The constant tensors of the ONNX ``model`` by name: its initializers and the outputs of its
    ``Constant`` nodes."""
    from onnx import numpy_helper

    consts = {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}
    for node in model.graph.node:
        if node.op_type == "Constant" and node.attribute and node.attribute[0].name == "value":
            consts[node.output[0]] = numpy_helper.to_array(node.attribute[0].t)
    return consts


def winograd_nodes(model) -> list[str]:
    """Names of the nodes of the Winograd depth form (:class:`spacepose.export.conv3d_as_2d.WinogradConv3dAs2d`)
    in the ONNX ``model``: the ``MatMul`` nodes whose constant operand is a depth transform
    (:func:`~spacepose.export.conv3d_as_2d.winograd_depth_transforms`) and the convolution between
    them. Their transforms widen the value range (coefficients up to 8), so int8 loses more there than
    anywhere else; :func:`quantize_int8` leaves them in float32."""
    from spacepose.export.conv3d_as_2d import winograd_depth_transforms

    consts = _constants(model)

    def is_transform(name: str) -> bool:
        a = consts.get(name)
        if a is None or a.ndim != 2 or a.dtype != np.float32:
            return False
        for depth, pad in [(a.shape[1], p) for p in range(3)] + [(a.shape[0] + 2 - 2 * p, p) for p in range(3)]:
            if depth < 1:
                continue
            try:
                t_in, t_out = winograd_depth_transforms(int(depth), pad)
            except ValueError:
                continue
            if any(t.shape == a.shape and np.array_equal(t, a) for t in (t_in, t_out)):
                return True
        return False

    names: list[str] = []
    consumers: dict[str, list] = {}
    for node in model.graph.node:
        for x in node.input:
            consumers.setdefault(x, []).append(node)
    for node in model.graph.node:
        if node.op_type != "MatMul" or not any(is_transform(x) for x in node.input):
            continue
        names.append(node.name)
        frontier = list(node.output)        # the grouped convolution fed by T_in, through reshapes
        while frontier:
            for nxt in consumers.get(frontier.pop(), []):
                if nxt.op_type in ("Reshape", "Transpose"):
                    frontier += list(nxt.output)
                elif nxt.op_type == "Conv":
                    names.append(nxt.name)
    return names


def polyphase_nodes(model) -> list[str]:
    """Names of the 2-D convolutions of the polyphase transposed-convolution form
    (:class:`spacepose.export.conv3d_as_2d.PolyphaseConvTranspose3dAs2d`) in the ONNX ``model``: each
    ``Conv`` whose output reaches, through ``Reshape`` / ``Slice`` / ``Transpose`` only, a grouped
    ``ConvTranspose`` with a constant 0/1 kernel (the pixel shuffle). Quantized, they cost poses
    (session 15, test split: one valid 146° pose and 7 valid poses off by more than 20° or 0.5 m, against
    none and 1 with them in float32, at about the same EPE, 1.83 against 1.85 px), and the per-tap form
    they replace was never quantized (``ConvTranspose`` is not among the quantized op types), so
    :func:`quantize_int8` leaves them in float32."""
    consts = _constants(model)
    producer = {o: node for node in model.graph.node for o in node.output}
    names: list[str] = []
    for node in model.graph.node:
        group = next((a.i for a in node.attribute if a.name == "group"), 1)
        kernel = consts.get(node.input[1]) if node.op_type == "ConvTranspose" and len(node.input) > 1 else None
        if kernel is None or group <= 1 or not np.all((kernel == 0) | (kernel == 1)):
            continue
        src = producer.get(node.input[0])
        while src is not None and src.op_type in ("Reshape", "Slice", "Transpose"):
            src = producer.get(src.input[0])
        if src is not None and src.op_type == "Conv" and src.name not in names:
            names.append(src.name)
    return names


def quantize_int8(src: str | Path, dst: str | Path, feeds: Sequence[dict[str, np.ndarray]],
                  op_types: Iterable[str] = ("Conv", "MatMul", "Gemm")) -> None:
    """Static QDQ int8 quantization of ``src`` calibrated on ``feeds`` (a list of input dicts); the
    Winograd depth form's nodes (:func:`winograd_nodes`) and the polyphase transposed convolutions
    (:func:`polyphase_nodes`) stay float32."""
    import onnx

    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    if not feeds:
        raise SpaceposeError(f"no calibration inputs for {src}")

    class Reader(CalibrationDataReader):
        def __init__(self) -> None:
            self._it = iter(feeds)

        def get_next(self):
            return next(self._it, None)

    with tempfile.TemporaryDirectory() as tmp:
        pre = Path(tmp) / "pre.onnx"
        quant_pre_process(str(src), str(pre), skip_symbolic_shape=True)
        graph = onnx.load(str(pre))
        kept = winograd_nodes(graph) + polyphase_nodes(graph)
        quantize_static(str(pre), str(dst), Reader(), quant_format=QuantFormat.QDQ, per_channel=True,
                        activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                        op_types_to_quantize=list(op_types), nodes_to_exclude=kept)
    _copy_metadata(Path(src), Path(dst), "int8", {"calibration_inputs": len(feeds), "op_types": list(op_types),
                                                   "float32_nodes": len(kept)})


def convert_fp16(src: str | Path, dst: str | Path) -> None:
    """float16 weights and activations, float32 graph inputs and outputs."""
    import onnx
    from onnxruntime.transformers.float16 import convert_float_to_float16

    model = convert_float_to_float16(onnx.load(str(src)), keep_io_types=True)
    onnx.save(model, str(dst))
    _copy_metadata(Path(src), Path(dst), "fp16", {})


def quantize_bundle(bundle_dir: str | Path | None, out: str | Path, precision: str, *, dataset: str | Path | None = None,
                    calib_frames: int = 32, force: bool = False) -> Path:
    """Write a ``precision`` copy of the bundle at ``bundle_dir`` (default: shipped) into ``out``."""
    from spacepose.bundle import load_bundle

    if precision not in PRECISIONS:
        raise SpaceposeError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    src = load_bundle(bundle_dir)
    src_dir = Path(src.path)
    out = Path(out)
    if out.resolve() == src_dir.resolve():
        raise SpaceposeError("--out must differ from the source bundle (it is never modified)")
    if out.exists() and any(out.iterdir()) and not force:
        raise SpaceposeError(f"{out} exists and is not empty (pass --force to overwrite)")
    out.mkdir(parents=True, exist_ok=True)
    stereo_src, pose_src = Path(src.stereo_path), Path(src.pose_path)
    if precision == "int8":
        if dataset is None:
            raise SpaceposeError("int8 needs a dataset to calibrate on (--calib-data)")
        stereo_feeds, pose_feeds = record_calibration_feeds(src_dir, dataset, calib_frames)
        quantize_int8(stereo_src, out / stereo_src.name, stereo_feeds)
        quantize_int8(pose_src, out / pose_src.name, pose_feeds)
    else:
        convert_fp16(stereo_src, out / stereo_src.name)
        convert_fp16(pose_src, out / pose_src.name)
    if src.flip_classifier is not None:   # small, and it decides flips: it stays float32 (model card)
        shutil.copyfile(src_dir / src.flip_classifier.file, out / src.flip_classifier.file)
    if src.outline_refiner is not None:   # small, and it shapes the polish's outline: float32 too
        shutil.copyfile(src_dir / src.outline_refiner.file, out / src.outline_refiner.file)
    manifest = json.loads((src_dir / "bundle.json").read_text())
    (out / "bundle.json").write_text(json.dumps(manifest, indent=1) + "\n")
    card = (src_dir / "MODEL_CARD.md").read_text(encoding="utf-8") if (src_dir / "MODEL_CARD.md").exists() else ""
    header = (f"# {precision} copy of `{src_dir}`\n\n"
              f"Made by `spacepose quantize {src_dir} --out {out} --precision {precision}"
              + (f" --calib-data {dataset} --calib-frames {calib_frames}`" if precision == "int8" else "`")
              + ". Measure its accuracy with `spacepose eval-stereo DATASET --bundle` / `eval-pose DATASET --bundle` "
              "on this folder: **the numbers in the card below are those of the float32 source graphs.**\n\n---\n\n")
    (out / "MODEL_CARD.md").write_text(header + card, encoding="utf-8")
    load_bundle(out)  # the copy must pass the same contract checks as the source
    log.info("wrote %s bundle %s", precision, out)
    return out
