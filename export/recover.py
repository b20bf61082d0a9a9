"""Recover torch weights from an exported ONNX graph, so a shipped model can be fine-tuned.

A shipped bundle holds ONNX graphs, not training checkpoints. The exporter keeps most parameters under
their ``state_dict`` names, but it folds every BatchNorm into the convolution before it (the graph
holds ``W * g / sqrt(v + eps)`` and ``b - m * g / sqrt(v + eps)`` as anonymous ``onnx::Conv_*``
tensors) and stores ``nn.Linear`` weights transposed for ``MatMul``.

:func:`recover_state_dict` undoes this with a *probe*: a copy of the model whose every parameter is
filled with distinct random values and whose BatchNorms are made near-identities (gamma, variance
1 +- 0.1 %, mean +- 0.001, random beta) is exported with the same exporter. In the probe graph each
initializer then equals one parameter (flattened, or transposed for a 2-D weight), so its source
is found by value. The shipped graph must have the same nodes in the same order; its initializer at
the same (node, input) position is written back through that map. A folded BatchNorm comes back as
an identity BatchNorm (gamma 1, mean 0, variance 1 - eps) carrying the folded bias, with the folded
weight in the convolution: the eval-mode function is exact, so fine-tune such a model with its
BatchNorms frozen (:func:`freeze_batchnorm`).

The caller checks the result against onnxruntime (``tests/export/test_recover.py`` does).
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import torch
from torch import nn

from spacepose.errors import SpaceposeError
from spacepose.export.conv3d_as_2d import WINOGRAD_G, polyphase_kernel_index

__all__ = ["RecoveryReport", "recover_state_dict", "freeze_batchnorm", "checkpoint_from_graph", "checkpoint_folds_bn"]

log = logging.getLogger(__name__)

_BN = (nn.BatchNorm1d, nn.BatchNorm2d, nn.BatchNorm3d)


@dataclass(frozen=True)
class RecoveryReport:
    """What :func:`recover_state_dict` set: ``recovered`` state keys, ``folded_bn`` BatchNorm module
    names rebuilt as identities, and ``missing`` float state keys no graph initializer fed (parameters the
    exported forward never reads, e.g. training-only heads; left at their values in ``model``)."""

    recovered: tuple[str, ...]
    folded_bn: tuple[str, ...]
    missing: tuple[str, ...]


def _initializer_positions(proto) -> tuple[list[tuple[str, str]], list[tuple[int, int, str]]]:
    """(op type, node name) of the non-Identity nodes, and (node index, input index, initializer name)
    for every input of those nodes that is an initializer, directly or through Identity nodes (the
    exporter deduplicates equal initializers with Identity nodes, so their number depends on the values)."""
    names = {init.name for init in proto.graph.initializer}
    alias: dict[str, str] = {}
    for node in proto.graph.node:
        if node.op_type == "Identity" and len(node.input) == 1:
            src = alias.get(node.input[0], node.input[0])
            if src in names:
                alias[node.output[0]] = src
    nodes = [n for n in proto.graph.node if not (n.op_type == "Identity" and n.output[0] in alias)]
    positions = [(i, j, alias.get(x, x)) for i, node in enumerate(nodes) for j, x in enumerate(node.input)
                 if alias.get(x, x) in names]
    return [(n.op_type, n.name) for n in nodes], positions


def _pair_initializers(nodes_a, pos_a, nodes_b, pos_b, where: str) -> list[tuple[str, str | None]]:
    """(probe initializer, shipped initializer) pairs that feed the same node input.

    Graphs of the same export code pair by position. A graph exported by an older version of the code
    (other weight-free nodes, e.g. a rewritten lookup) pairs by (node name, input index): the exporter
    names nodes after the module path, so weight-bearing nodes keep their names. A probe initializer
    whose node the shipped graph lacks is paired with None (the caller accepts that only for
    constants that are not weights)."""
    if nodes_a == nodes_b and [p[:2] for p in pos_a] == [p[:2] for p in pos_b]:
        return [(a[2], b[2]) for a, b in zip(pos_a, pos_b)]
    names_a, names_b = [n[1] for n in nodes_a], [n[1] for n in nodes_b]
    if not all(names_a) or not all(names_b) or len(set(names_a)) < len(names_a) or len(set(names_b)) < len(names_b):
        raise SpaceposeError(f"{where}: graph structure differs from this model's export "
                             f"({len(nodes_b)} vs {len(nodes_a)} nodes) and its node names cannot pair them")
    shipped = {(nodes_b[i][1], j): (nodes_b[i][0], name) for i, j, name in pos_b}
    pairs: list[tuple[str, str | None]] = []
    for i, j, name in pos_a:
        found = shipped.get((nodes_a[i][1], j))
        pairs.append((name, found[1] if found is not None and found[0] == nodes_a[i][0] else None))
    return pairs


def _probe(model: nn.Module, seed: int) -> tuple[nn.Module, dict[str, str]]:
    """Copy of ``model`` with distinct random floats everywhere and near-identity BatchNorms (gamma and
    variance 1 +- 0.1 %, mean +- 0.001, random beta).

    Returns the probe and, for each BatchNorm bias key, its module name."""
    probe = copy.deepcopy(model).eval()
    gen = torch.Generator().manual_seed(seed)
    bn_of_bias: dict[str, str] = {}
    with torch.no_grad():
        for name, module in probe.named_modules():
            if isinstance(module, _BN):
                bn_of_bias[f"{name}.bias" if name else "bias"] = name
        for key, tensor in probe.state_dict(keep_vars=True).items():
            if not tensor.is_floating_point():
                continue
            tensor.copy_(torch.randn(tensor.shape, generator=gen) * 0.5 + 0.01)
        for name, module in probe.named_modules():
            if isinstance(module, _BN) and module.affine and module.track_running_stats:
                # distinct gammas (no deduplicated initializers) close to 1 (a folded conv stays recognisable)
                module.weight.copy_(1.0 + 1e-3 * torch.randn(module.weight.shape, generator=gen))
                module.running_mean.copy_(1e-3 * torch.randn(module.running_mean.shape, generator=gen))
                module.running_var.copy_(1.0 + 1e-3 * torch.randn(module.running_var.shape, generator=gen))
    return probe, bn_of_bias


def _tap_combinations(kd: int) -> list[np.ndarray]:
    """Coefficient matrices (r, kd) of the forms :mod:`spacepose.export.conv3d_as_2d` gives a 5-D
    convolution weight's ``kd`` depth taps: each tap alone, all taps stacked, and for 3 taps each
    Winograd kernel transform row alone and all rows stacked."""
    bases = [np.eye(kd)] + ([WINOGRAD_G] if kd == WINOGRAD_G.shape[1] else [])
    return [m for base in bases for m in [base[i:i + 1] for i in range(len(base))] + [base]]


def _polyphase_indices(shape: tuple[int, ...], value_shape: tuple[int, ...]) -> list[np.ndarray]:
    """The kernel layouts :class:`~spacepose.export.conv3d_as_2d.PolyphaseConvTranspose3dAs2d` could give a
    ``ConvTranspose3d`` weight of ``shape`` as a 2-D kernel of ``value_shape``: one flat-index array per
    stride (each a divisor of its kernel axis) that yields that shape."""
    divisors = [[s for s in range(1, k + 1) if k % s == 0] for k in shape[2:]]
    out = []
    for stride in itertools.product(*divisors):
        if (stride[0] * shape[1] * stride[1] * stride[2], shape[2] // stride[0] * shape[0],
                shape[3] // stride[1], shape[4] // stride[2]) == tuple(value_shape):
            out.append(polyphase_kernel_index(shape, stride))
    return out


def _match(value: np.ndarray, candidates: dict[str, np.ndarray]) -> tuple[str, object] | None:
    """The state key whose values are closest to ``value``, within 1 % (a folded BatchNorm scales a
    convolution by its probe gamma, 1 +- 0.3 %), and how it is laid out: ``"flat"`` (same values,
    flattened), ``"T"`` (a 2-D transpose), ``("taps", M)``: the combinations ``sum_j M[i, j] ref[:, :, j]``
    of the depth taps of a 5-D convolution weight, stacked along the outputs (one tap, the taps
    stacked, a Winograd kernel transform row, or all of them, as :mod:`spacepose.export.conv3d_as_2d`
    exports them; :func:`_tap_combinations`), or ``("index", I)``: ``ref.flat[I]``, a permutation of a
    transposed convolution's weight (the polyphase kernel; :func:`_polyphase_indices`)."""
    flat = value.reshape(-1).astype(np.float64)
    scale = float(np.max(np.abs(flat))) + 1e-12
    best: tuple[float, str, object] | None = None
    for key, ref in candidates.items():
        options: list[tuple[np.ndarray, object]] = []
        if ref.size == flat.size:
            options.append((ref.reshape(-1), "flat"))
            if ref.ndim == 2 and value.shape == ref.shape[::-1]:
                options.append((ref.T.reshape(-1), "T"))
        if ref.ndim == 5 and value.ndim == 4 and ref.size == flat.size:
            flat_ref = ref.reshape(-1)
            options.extend((flat_ref[idx].reshape(-1), ("index", idx)) for idx in _polyphase_indices(ref.shape, value.shape))
        if ref.ndim == 5 and value.ndim == 4 and ref.shape[2] > 1:
            taps = np.moveaxis(ref, 2, 0)                               # (kd, C_out, C_in, kh, kw)
            for m in _tap_combinations(ref.shape[2]):
                if len(m) * taps[0].size == flat.size:
                    options.append((np.tensordot(m, taps, axes=1).reshape(-1), ("taps", tuple(map(tuple, m)))))
        for arr, layout in options:
            err = float(np.max(np.abs(arr - flat))) / scale
            if best is None or err < best[0]:
                best = (err, key, layout)
    if best is None or best[0] > 1e-2:
        return None
    return best[1], best[2]


def recover_state_dict(model: nn.Module, onnx_path: str | os.PathLike,
                       export: Callable[[nn.Module, Path], object], *, prefix: str = "",
                       seed: int = 0) -> RecoveryReport:
    """Load the weights of the graph at ``onnx_path`` into ``model`` (in place).

    Args:
        model: a freshly built model of the graph's architecture (its config from the graph metadata).
        onnx_path: the exported graph.
        export: ``export(module, path)`` writes ``module`` to ``path`` exactly as ``onnx_path`` was
            written (same wrapper, input size, iteration count, opset).
        prefix: prefix of the graph's parameter names (``"model."`` when a wrapper held the model).
        seed: seed of the probe's random values.

    Raises:
        SpaceposeError: the graphs differ in structure, or a graph initializer has no source.
    """
    import onnx
    from onnx import numpy_helper

    shipped = onnx.load(str(onnx_path))
    probe, bn_of_bias = _probe(model, seed)
    with tempfile.TemporaryDirectory() as tmp:
        probe_path = Path(tmp) / "probe.onnx"
        export(probe, probe_path)
        probe_proto = onnx.load(str(probe_path))
    nodes_a, pos_a = _initializer_positions(probe_proto)
    nodes_b, pos_b = _initializer_positions(shipped)
    pairs = _pair_initializers(nodes_a, pos_a, nodes_b, pos_b, str(onnx_path))
    probe_vals = {i.name: numpy_helper.to_array(i) for i in probe_proto.graph.initializer}
    shipped_vals = {i.name: numpy_helper.to_array(i) for i in shipped.graph.initializer}
    state = model.state_dict()
    probe_state = {k: v.detach().cpu().numpy() for k, v in probe.state_dict().items() if v.is_floating_point()}
    by_name = {prefix + k: k for k in probe_state}

    assigned: dict[str, np.ndarray] = {}
    taps: dict[str, list[tuple[tuple[float, ...], np.ndarray]]] = {}
    folded: set[str] = set()
    for name_a, name_b in pairs:
        value_a = probe_vals[name_a]
        if value_a.dtype.kind != "f":
            continue                                    # shapes, indices: not weights
        if name_b is None:
            if value_a.size <= 1:
                continue                                # a scalar constant of a node the shipped graph lacks
            raise SpaceposeError(f"{onnx_path}: graph structure differs from this model's export: the node fed "
                                 f"by {name_a} {list(value_a.shape)} is not in it; is the config the one it was "
                                 "exported with?")
        value_b = shipped_vals[name_b]
        key = by_name.get(name_a)
        layout: object = "flat"
        if key is None or probe_state[key].size != value_a.size or not np.allclose(
                probe_state[key].reshape(-1), value_a.reshape(-1), rtol=1e-6, atol=1e-7):
            found = _match(value_a, probe_state)
            if found is None:
                if value_a.size <= 1:
                    continue                            # a folded scalar constant (eps, scale)
                raise SpaceposeError(f"{onnx_path}: initializer {name_b} {list(value_b.shape)} has no source parameter")
            key, layout = found
        if isinstance(layout, tuple) and layout[0] == "index":  # a permutation of the weight
            value = np.empty(state[key].numel(), dtype=np.float32)
            value[layout[1].reshape(-1)] = np.asarray(value_b).reshape(-1)
            assigned[key] = value.reshape(state[key].shape)
            continue
        if isinstance(layout, tuple):                   # combinations of depth taps, stacked along the outputs
            rows = layout[1]
            for row, part in zip(rows, np.asarray(value_b).reshape(len(rows), -1)):
                taps.setdefault(key, []).append((row, part))
            continue
        value = value_b.T if layout == "T" else value_b
        assigned[key] = np.ascontiguousarray(value).reshape(state[key].shape)
        if key in bn_of_bias and not name_a.startswith(prefix + key):
            folded.add(bn_of_bias[key])

    for key, parts in taps.items():
        shape = tuple(state[key].shape)
        coeffs = np.array([c for c, _ in parts])                        # (parts, kd)
        if np.linalg.matrix_rank(coeffs) < shape[2]:
            raise SpaceposeError(f"{onnx_path}: the graph holds too few combinations of the depth taps of {key} "
                                 f"{list(shape)} to recover them")
        values = np.stack([v.reshape(-1).astype(np.float64) for _, v in parts])
        solved = np.linalg.lstsq(coeffs, values, rcond=None)[0]         # (kd, rest): tap j, flattened
        assigned[key] = np.moveaxis(solved.reshape((shape[2],) + shape[:2] + shape[3:]), 0, 2)

    modules = dict(model.named_modules())
    with torch.no_grad():
        for key, value in assigned.items():
            state[key].copy_(torch.from_numpy(value.astype(np.float32)))
        for name in sorted(folded):
            bn = modules[name]
            bn.weight.fill_(1.0)
            bn.running_mean.zero_()
            bn.running_var.fill_(1.0 - bn.eps)
    set_by_fold = {f"{n}.{s}" for n in folded for s in ("weight", "running_mean", "running_var")}
    missing = tuple(k for k, v in state.items()
                    if v.is_floating_point() and k not in assigned and k not in set_by_fold)
    if missing:
        log.warning("%d state entries not in %s (left as they were): %s", len(missing), onnx_path, ", ".join(missing[:8]))
    log.info("recovered %d tensors from %s (%d folded BatchNorms)", len(assigned), onnx_path, len(folded))
    return RecoveryReport(tuple(sorted(assigned)), tuple(sorted(folded)), missing)


class _FrozenBN:
    """Mixin: a BatchNorm that stays in eval mode (running statistics) whatever ``train()`` says."""

    def train(self, mode: bool = True):  # noqa: D401 - nn.Module API
        super().train(False)
        return self


_FROZEN = {cls: type(f"Frozen{cls.__name__}", (_FrozenBN, cls), {}) for cls in _BN}


def freeze_batchnorm(model: nn.Module) -> int:
    """Make every BatchNorm of ``model`` keep its running statistics in training; returns how many.

    A recovered model's BatchNorms hold folded identities, not batch statistics, so they must not
    renormalise by batch while the rest fine-tunes. Their affine parameters still train. The state
    keys and the exported graph are those of ordinary BatchNorms.
    """
    n = 0
    for module in model.modules():
        if type(module) in _FROZEN:
            module.__class__ = _FROZEN[type(module)]
            module.train(False)
            n += 1
    return n


def checkpoint_from_graph(onnx_path: str | os.PathLike) -> dict:
    """A training checkpoint (the trainers' format, usable with ``--init``) rebuilt from a shipped graph.

    The graph's metadata names its kind and config. The checkpoint carries ``folded_bn`` (fine-tune
    with frozen BatchNorms), ``step`` = the training steps the metadata records, and ``source`` =
    the graph path; it holds no optimiser state. The recovered model is checked against onnxruntime
    on the exporter's parity inputs; a difference above the exporters' tolerances raises.
    """
    from spacepose.export import onnx_pose, onnx_stereo
    from spacepose.onnx_session import read_metadata

    meta = read_metadata(onnx_path)
    kind = meta.get("kind")
    training = meta.get("training") or {}
    if kind == "stereo":
        from spacepose.models.stereo_config import StereoConfig
        from spacepose.models.tsca_stereo import TSCAStereo

        config = StereoConfig.from_dict(meta["config"])
        size, iters = tuple(int(v) for v in meta["input_size"]), int(meta["iters"])
        model = TSCAStereo(config).eval()
        flags = meta.get("export") or {}  # an exporter option absent from older graphs' metadata was off
        report = recover_state_dict(model, onnx_path, lambda m, p: onnx_stereo.export_stereo(
            m, p, size=size, iters=iters, metadata={}, force=True, rewrite_convs=bool(flags.get("conv3d_as_2d")),
            rewrite_transposed=bool(flags.get("conv_transpose3d_as_2d")),
            rewrite_narrow=bool(flags.get("narrow_conv3d_as_2d")),
            rewrite_winograd=bool(flags.get("conv3d_depth_winograd")),
            rewrite_polyphase=bool(flags.get("conv_transpose3d_polyphase"))), prefix="model.")
        diff = onnx_stereo.parity_check(model, onnx_path, size=size, iters=iters)
        tolerance = 1e-3
        ckpt = {"kind": "stereo", "stereo_config": config.to_dict()}
    elif kind == "pose":
        from spacepose.models.pose_config import PoseNetConfig
        from spacepose.models.pose_net import PoseNet

        config = PoseNetConfig.from_dict(meta["config"])
        model = PoseNet(config).eval()
        report = recover_state_dict(model, onnx_path, lambda m, p: onnx_pose.export_pose(
            m, p, metadata={}, force=True))
        diff = onnx_pose.parity_check(model, onnx_path)["max"]
        tolerance = 1e-3
        ckpt = {"kind": "pose", "net_config": dataclasses.asdict(config), "keypoints": meta.get("keypoints"),
                "centre": meta.get("centre"), "target": meta.get("target")}
    elif kind == "flip":
        from spacepose.export import onnx_flip
        from spacepose.models.flip_net import FlipNet, FlipNetConfig

        raw = dict(meta["config"])
        config = FlipNetConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in raw.items()})
        model = FlipNet(config).eval()
        report = recover_state_dict(model, onnx_path, lambda m, p: onnx_flip.write_flip_graph(m, p, {}))
        diff = onnx_flip.parity_check(model, onnx_path)
        tolerance = onnx_flip.PARITY_TOLERANCE
        ckpt = {"kind": "flip", "net_config": dataclasses.asdict(config), "samples": int(meta.get("samples") or 0),
                "target": meta.get("target"), "axis": meta.get("axis")}
        training = {"step": meta.get("steps")}
    else:
        raise SpaceposeError(f"{onnx_path}: metadata kind {kind!r} is not 'stereo', 'pose' or 'flip'")
    if not diff < tolerance:
        raise SpaceposeError(f"{onnx_path}: the recovered model differs from the graph by {diff:.3g} (> {tolerance})")
    log.info("%s: recovered %s model matches the graph to %.2g", onnx_path, kind, diff)
    ckpt.update({"model": model.state_dict(), "step": int(training.get("step") or 0), "source": str(onnx_path),
                 "folded_bn": list(report.folded_bn), "not_in_graph": list(report.missing), "parity": float(diff)})
    return ckpt


def checkpoint_folds_bn(ckpt: dict) -> bool:
    """Whether a checkpoint's BatchNorms are folded identities (fine-tune with :func:`freeze_batchnorm`)."""
    return bool(ckpt.get("folded_bn"))
