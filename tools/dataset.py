"""Write a synthetic stereo dataset (layout of spec/CONVENTIONS.md), sharded and resumable.

Layout::

    DATASET/
      dataset.json            manifest: target (+sha256), seed, count, size, depth range, rig, generator
      rig.yaml                the rig the frames were rendered with (OpenCV FileStorage)
      left/<name>.png  right/<name>.png          8-bit RGB after degradations
      disparity/<name>.pfm    exact left disparity fx*B/Z on target pixels, 0 elsewhere
      depth/<name>.pfm        left ray-cast depth Z (m) on target pixels, 0 elsewhere (not with
                              ``--no-depth``: the manifest then says ``"depth_maps": false``)
      mask/<name>.png  mask_right/<name>.png     255 on target pixels of the left / right image
      meta/<name>.json        the frame's label (written last: the frame's commit marker)
      labels.jsonl            all labels in frame order (rebuilt from meta/ after every run)

Determinism: frame ``i`` is a pure function of (target, rig, size, seed, i): its generator is
``SeedSequence([seed, i])``; its split and regime come from blocks of consecutive indices (one test
frame in every block of 10 -> exact 9:1; each regime once in every block of 4 -> equal shares), so
any shard, machine or resume renders the same frame identically.

Sharding: ``--shard k/K`` (1 <= k <= K) renders indices ``i`` with ``i % K == k - 1``. Resuming skips
frames whose files all exist. A folder that holds anything else than this dataset is refused.
"""

from __future__ import annotations

import json
import logging
import multiprocessing
import os
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from spacepose.errors import DatasetError

log = logging.getLogger(__name__)

__all__ = [
    "GENERATOR",
    "MANIFEST",
    "FRAME_FILES",
    "RenderConfig",
    "frame_name",
    "split_of",
    "regime_of",
    "frame_generators",
    "render_frame",
    "prepare_dataset",
    "render_dataset",
    "frame_complete",
    "frame_folders",
    "require_depth",
    "stores_depth",
    "shard_indices",
    "collect_labels",
    "parse_shard",
]

GENERATOR = "spacepose.tools.render/1"
MANIFEST = "dataset.json"
#: folder -> extension of every per-frame file; meta/ is written last
FRAME_FILES = {
    "left": ".png",
    "right": ".png",
    "disparity": ".pfm",
    "depth": ".pfm",
    "mask": ".png",
    "mask_right": ".png",
    "meta": ".json",
}
TEST_BLOCK = 10  # one test frame per block of 10 consecutive indices (9:1)


@dataclass(frozen=True)
class RenderConfig:
    """What defines a dataset (everything in the manifest's identity).

    Attributes:
        target: shipped target name or mesh path.
        count: number of frames (train + test).
        size: (width, height) of the images.
        seed: dataset seed.
        depth_range: (min, max) of the target's z in metres.
        depth_maps: write ``depth/<name>.pfm`` (the ray-cast depth; CONVENTIONS.md makes it optional).
            ``False`` halves the maps' disk use (an evaluation set needs no depth: 1.2 MB a frame
            at 640x480, 4.9 MB at 1280x960); the manifest records it (``"depth_maps": false``).
    """

    target: str = "tdrs"
    count: int = 2000
    size: tuple[int, int] = (640, 480)
    seed: int = 0
    depth_range: tuple[float, float] = (10.0, 50.0)
    depth_maps: bool = True

    def __post_init__(self) -> None:
        if isinstance(self.count, bool) or not isinstance(self.count, (int, np.integer)) or self.count < 1:
            raise DatasetError(f"count must be a positive integer, got {self.count!r}")
        w, h = self.size
        if int(w) < 16 or int(h) < 16:
            raise DatasetError(f"image size must be at least 16x16, got {w}x{h}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise DatasetError(f"seed must be a non-negative integer, got {self.seed!r}")
        object.__setattr__(self, "size", (int(w), int(h)))
        object.__setattr__(self, "depth_range", (float(self.depth_range[0]), float(self.depth_range[1])))
        object.__setattr__(self, "depth_maps", bool(self.depth_maps))


def frame_name(index: int) -> str:
    """File stem of frame ``index`` (zero-padded, sorts in frame order)."""
    return f"{index:06d}"


def _block_permutation(seed: int, block: int, size: int, salt: int) -> np.ndarray:
    return np.random.default_rng([seed, block, salt]).permutation(size)


def split_of(seed: int, index: int) -> str:
    """``"test"`` for exactly one index in every block of 10 (chosen by the seed), else ``"train"``."""
    block, pos = divmod(index, TEST_BLOCK)
    return "test" if _block_permutation(seed, block, TEST_BLOCK, 0x5E1)[0] == pos else "train"


def regime_of(seed: int, index: int) -> str:
    """Illumination regime: each of the four once in every block of 4 indices, order by the seed."""
    from .render import REGIMES

    block, pos = divmod(index, len(REGIMES))
    return REGIMES[int(_block_permutation(seed, block, len(REGIMES), 0x4E6)[pos])]


def frame_generators(seed: int, index: int) -> tuple[np.random.Generator, np.random.Generator, np.random.Generator, np.random.Generator]:
    """Independent generators (scene, degradation parameters, left noise, right noise) of a frame."""
    children = np.random.SeedSequence([int(seed), int(index)]).spawn(4)
    return tuple(np.random.default_rng(c) for c in children)  # type: ignore[return-value]


@dataclass(frozen=True, eq=False)
class Frame:
    """One rendered, degraded frame ready to be written."""

    name: str
    left: np.ndarray  # uint8 (H,W,3)
    right: np.ndarray
    disparity: np.ndarray  # float32 (H,W)
    depth: np.ndarray
    mask: np.ndarray  # bool
    mask_right: np.ndarray
    label: dict = field(repr=False)


def render_frame(target, camera, sampler, seed: int, index: int) -> Frame:
    """Render frame ``index`` of the dataset with ``seed`` (deterministic)."""
    from .degrade import apply_degradations, sample_degradations, to_uint8
    from .render import render_stereo, rotation_to_quaternion, sample_scene

    rng_scene, rng_deg, rng_left, rng_right = frame_generators(seed, index)
    regime = regime_of(seed, index)
    scene = sample_scene(target, camera, rng_scene, regime, sampler)
    clean = render_stereo(target, camera, scene)
    params = sample_degradations(rng_deg, camera.size[0])
    left = to_uint8(apply_degradations(clean.left, params, rng_left))
    right = to_uint8(apply_degradations(clean.right, params, rng_right))
    mask = clean.mask
    ys, xs = np.nonzero(mask)
    d = clean.disparity[mask]
    illumination = scene.to_json()
    label = {
        "frame": frame_name(index),
        "index": int(index),
        "split": split_of(seed, index),
        "R": [[float(x) for x in row] for row in scene.R],
        "t": [float(x) for x in scene.t],
        "q_wxyz": [float(x) for x in rotation_to_quaternion(scene.R)],
        "regime": regime,
        "degradations": params,
        "sun_dir": illumination.pop("sun_dir"),
        "illumination": {k: v for k, v in illumination.items() if k != "regime"},
        "exposure": round(float(clean.exposure), 6),
        "mask_pixels": int(mask.sum()),
        "bbox_xyxy": [int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1] if len(xs) else None,
        "disparity_range": [round(float(d.min()), 4), round(float(d.max()), 4)] if len(d) else None,
    }
    return Frame(
        name=frame_name(index),
        left=left,
        right=right,
        disparity=clean.disparity,
        depth=clean.depth,
        mask=mask,
        mask_right=clean.mask_right,
        label=label,
    )


def _frame_path(root: Path, folder: str, name: str) -> Path:
    return root / folder / f"{name}{FRAME_FILES[folder]}"


def frame_folders(depth_maps: bool = True) -> tuple[str, ...]:
    """The per-frame folders of a dataset (:data:`FRAME_FILES`, without ``depth`` when not ``depth_maps``)."""
    return tuple(folder for folder in FRAME_FILES if depth_maps or folder != "depth")


def stores_depth(root: str | os.PathLike) -> bool:
    """Whether the dataset at ``root`` stores ``depth/`` maps (its manifest's ``depth_maps``, default true;
    true without a readable manifest, as every dataset before the option)."""
    try:
        manifest = json.loads((Path(root) / MANIFEST).read_text())
    except (OSError, ValueError):
        return True
    return not (isinstance(manifest, dict) and manifest.get("depth_maps", True) is False)


def require_depth(root: str | os.PathLike) -> None:
    """Raise :class:`DatasetError` when the dataset at ``root`` was rendered without depth maps."""
    if not stores_depth(root):
        raise DatasetError(f"{root} was rendered with --no-depth and holds no depth/ maps; render it again "
                           "without --no-depth (same options) for a command that reads depth")


def frame_complete(root: str | os.PathLike, name: str, depth_maps: bool = True) -> bool:
    """True when every file of frame ``name`` exists (meta last, so a crash leaves it incomplete);
    ``depth_maps`` false: the depth map is not asked for."""
    root = Path(root)
    return all(_frame_path(root, folder, name).is_file() for folder in frame_folders(depth_maps))


def _atomic_write_text(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_frame(root: str | os.PathLike, frame: Frame, depth_maps: bool = True) -> None:
    """Write all files of ``frame`` (the depth map only with ``depth_maps``); the meta JSON goes last and
    atomically."""
    from spacepose.imageio import write_image, write_pfm

    root = Path(root)
    name = frame.name
    write_image(_frame_path(root, "left", name), frame.left)
    write_image(_frame_path(root, "right", name), frame.right)
    write_pfm(_frame_path(root, "disparity", name), frame.disparity)
    if depth_maps:
        write_pfm(_frame_path(root, "depth", name), frame.depth)
    write_image(_frame_path(root, "mask", name), frame.mask.astype(np.uint8) * 255)
    write_image(_frame_path(root, "mask_right", name), frame.mask_right.astype(np.uint8) * 255)
    _atomic_write_text(_frame_path(root, "meta", name), json.dumps(frame.label) + "\n")


# ---------------------------------------------------------------------------------------------
# manifest and folder checks


def _identity(config: RenderConfig, target, rig) -> dict:
    identity = {
        "format": "spacepose-dataset/1",
        "generator": GENERATOR,
        "target": target.name,
        "target_sha256": target.sha256,
        "seed": int(config.seed),
        "count": int(config.count),
        "size": list(config.size),
        "depth_range": list(config.depth_range),
        "rig": {
            "fx": float(rig.M1[0, 0]),
            "fy": float(rig.M1[1, 1]),
            "cx": float(rig.M1[0, 2]),
            "cy": float(rig.M1[1, 2]),
            "baseline_m": float(rig.baseline_m),
        },
        "split": {"test_per_block": 1, "block": TEST_BLOCK},
    }
    if not config.depth_maps:   # only then: the manifests of datasets with depth stay as they were
        identity["depth_maps"] = False
    return identity


def _compare(existing: dict, wanted: dict) -> list[str]:
    diffs = []
    for key, value in wanted.items():
        have = existing.get(key)
        if isinstance(value, dict) and isinstance(have, dict):
            same = all(np.isclose(have.get(k, np.nan), v) if isinstance(v, float) else have.get(k) == v for k, v in value.items())
        elif isinstance(value, float):
            same = isinstance(have, (int, float)) and np.isclose(have, value)
        else:
            same = have == value or (isinstance(value, list) and isinstance(have, list) and np.allclose(have, value))
        if not same:
            diffs.append(f"{key}: folder has {have!r}, asked for {value!r}")
    return diffs


def prepare_dataset(root: str | os.PathLike, config: RenderConfig, target, rig) -> dict:
    """Create the dataset folder (manifest, rig.yaml, sub-folders) or check that it is this dataset.

    Safe against several shards starting at once (the manifest is created exclusively).

    Raises:
        DatasetError: ``root`` is a file, holds files but no manifest, or holds a different dataset.
    """
    from spacepose.calibration.rig import load_rig, save_rig

    root = Path(root)
    if root.exists() and not root.is_dir():
        raise DatasetError(f"{root} exists and is not a folder")
    root.mkdir(parents=True, exist_ok=True)
    manifest_path = root / MANIFEST
    wanted = _identity(config, target, rig)
    if not manifest_path.exists():
        others = [p.name for p in root.iterdir() if not p.name.startswith(".")]
        if others:
            raise DatasetError(
                f"{root} is not empty and holds no {MANIFEST} (found {sorted(others)[:5]}); refusing to write a dataset "
                "into it: choose an empty or new folder"
            )
        try:
            fd = os.open(manifest_path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            pass  # another shard won the race: compare below
        else:
            with os.fdopen(fd, "w") as fh:
                json.dump(wanted, fh, indent=2)
                fh.write("\n")
    try:
        existing = json.loads(manifest_path.read_text())
    except (OSError, ValueError) as err:
        raise DatasetError(f"{manifest_path} is unreadable or corrupt: {err}") from err
    if not isinstance(existing, dict):
        raise DatasetError(f"{manifest_path} is not a dataset manifest")
    diffs = _compare(existing, wanted)
    if existing.get("depth_maps", True) is not wanted.get("depth_maps", True):
        diffs.append(f"depth_maps: folder has {existing.get('depth_maps', True)!r}, asked for "
                     f"{wanted.get('depth_maps', True)!r} (--no-depth must match)")
    if diffs:
        raise DatasetError(
            f"{root} holds another dataset ({'; '.join(diffs)}); refusing to overwrite it: use another folder, "
            "or the same options to resume it"
        )
    rig_path = root / "rig.yaml"
    if rig_path.exists():
        if not load_rig(rig_path).allclose(rig, rtol=1e-9, atol=1e-9):
            raise DatasetError(f"{rig_path} differs from the rig asked for; refusing to overwrite it")
    else:
        try:
            save_rig(rig, rig_path, overwrite=False)
        except FileExistsError:
            pass
    for folder in frame_folders(config.depth_maps):
        (root / folder).mkdir(exist_ok=True)
    return existing


def parse_shard(text: str) -> tuple[int, int]:
    """Parse ``k/K`` (1 <= k <= K) into (k, K)."""
    try:
        k_text, n_text = str(text).split("/")
        k, n = int(k_text), int(n_text)
    except ValueError as err:
        raise DatasetError(f"--shard must look like k/K (for example 2/8), got {text!r}") from err
    if not (n >= 1 and 1 <= k <= n):
        raise DatasetError(f"--shard k/K needs 1 <= k <= K, got {text!r}")
    return k, n


def shard_indices(count: int, shard: tuple[int, int] = (1, 1)) -> range:
    """Frame indices of shard (k, K): every K-th index starting at k - 1."""
    k, n = shard
    return range(k - 1, count, n)


def collect_labels(root: str | os.PathLike) -> int:
    """Rebuild ``labels.jsonl`` (frame order) from the complete frames' meta files; return its line count."""
    root = Path(root)
    depth = stores_depth(root)
    lines = []
    for meta in sorted((root / "meta").glob("*.json")):
        if not frame_complete(root, meta.stem, depth):
            continue
        text = meta.read_text().strip()
        if text:
            lines.append(text)
    _atomic_write_text(root / "labels.jsonl", "\n".join(lines) + ("\n" if lines else ""))
    return len(lines)


# ---------------------------------------------------------------------------------------------
# rendering loop (optionally in worker processes)


_WORKER: dict = {}


def _setup(target_spec: str, rig, config: RenderConfig) -> dict:
    from .render import PoseSampler, StereoCamera
    from .targets import load_target

    target = load_target(target_spec)
    camera = StereoCamera.from_rig(rig)
    sampler = PoseSampler(camera, target.bounding_radius, config.depth_range)
    return {"target": target, "camera": camera, "sampler": sampler, "config": config}


def _init_worker(target_spec: str, rig, config: RenderConfig) -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    _WORKER.update(_setup(target_spec, rig, config))


def _render_and_write(task: tuple[str, int]) -> str:
    root, index = task
    w = _WORKER
    frame = render_frame(w["target"], w["camera"], w["sampler"], w["config"].seed, index)
    write_frame(root, frame, w["config"].depth_maps)
    return frame.name


def _rig_for(config: RenderConfig, rig=None):
    from spacepose.calibration.rig import paper_rig

    if rig is None:
        return paper_rig(*config.size)
    if tuple(rig.image_size) != tuple(config.size):
        return rig.scaled(*config.size)
    return rig


def render_dataset(
    root: str | os.PathLike,
    config: RenderConfig,
    *,
    shard: tuple[int, int] = (1, 1),
    workers: int = 2,
    rig=None,
    progress: Callable[[int, int], None] | None = None,
) -> dict:
    """Render (or resume) the frames of ``shard`` into ``root``; rebuild labels.jsonl at the end.

    Args:
        root: dataset folder (created if missing).
        config: dataset definition.
        shard: (k, K), 1-based.
        workers: processes (1 = render in this process).
        rig: an ideal parallel :class:`StereoRig` (default: the paper rig at ``config.size``).
        progress: called as ``progress(done, todo)`` after each frame.

    Returns:
        {"rendered": n, "skipped": n, "labels": n, "shard": "k/K"}.

    Raises:
        DatasetError / TargetError: bad target, bad depth range, foreign folder, bad shard.
    """
    from .render import PoseSampler, StereoCamera
    from .targets import load_target

    k, n = shard
    if not (n >= 1 and 1 <= k <= n):
        raise DatasetError(f"shard must satisfy 1 <= k <= K, got {k}/{n}")
    target = load_target(config.target)
    rig = _rig_for(config, rig)
    camera = StereoCamera.from_rig(rig)
    PoseSampler(camera, target.bounding_radius, config.depth_range)  # fail early on a bad depth range
    root = Path(root)
    prepare_dataset(root, config, target, rig)
    indices = [i for i in shard_indices(config.count, shard) if not frame_complete(root, frame_name(i), config.depth_maps)]
    skipped = len(shard_indices(config.count, shard)) - len(indices)
    log.info("shard %d/%d: %d frames to render, %d already complete", k, n, len(indices), skipped)
    tasks = [(str(root), i) for i in indices]
    done = 0
    if workers <= 1 or len(tasks) <= 1:
        _WORKER.update(_setup(config.target, rig, config))
        for task in tasks:
            _render_and_write(task)
            done += 1
            if progress:
                progress(done, len(tasks))
    else:
        ctx = multiprocessing.get_context("spawn")  # embree/TBB threads do not survive fork
        with ctx.Pool(workers, initializer=_init_worker, initargs=(config.target, rig, config)) as pool:
            for _ in pool.imap_unordered(_render_and_write, tasks, chunksize=1):
                done += 1
                if progress:
                    progress(done, len(tasks))
    labels = collect_labels(root)
    return {"rendered": done, "skipped": skipped, "labels": labels, "shard": f"{k}/{n}", "config": asdict(config)}


def iter_labels(root: str | os.PathLike) -> Iterable[dict]:
    """Yield the labels of ``root/labels.jsonl``."""
    with open(Path(root) / "labels.jsonl") as fh:
        for line in fh:
            if line.strip():
                yield json.loads(line)
