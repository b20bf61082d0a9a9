"""Stage timing, peak memory and the latency/memory budget of the flight runtime (stdlib + numpy).

* :class:`StageTimer` times named stages of one frame (``with timer.stage("stereo"): ...``); the
  :class:`~spacepose.estimator.PoseEstimator` reports these as ``PoseResult.timings_ms``.
* :func:`peak_rss_bytes` is the process's peak resident set size (``VmHWM`` in
  ``/proc/self/status``, falling back to ``resource.getrusage``): memory is measured, not assumed
  (onnxruntime's arena alone can inflate it by gigabytes).
* :class:`Budget` is what a flight computer allows: a pose rate, a peak RSS and a number of cores.
  :func:`load_budget` reads it from JSON or a flat ``key: value`` YAML file; :func:`check_budget`
  says which limits a profile breaks.
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from contextlib import contextmanager
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Iterator, Mapping, Sequence

import numpy as np

__all__ = [
    "StageTimer",
    "Budget",
    "DEFAULT_BUDGET",
    "load_budget",
    "peak_rss_bytes",
    "current_rss_bytes",
    "summarize_timings",
    "network_split",
    "check_budget",
    "budget_to_dict",
]

logger = logging.getLogger(__name__)


class StageTimer:
    """Wall-clock time of named stages, in milliseconds (``time.perf_counter``).

    A stage entered twice accumulates. ``timings_ms`` keeps the order in which stages first ran;
    ``total_ms`` is their sum. Not thread-safe: use one timer per frame.
    """

    def __init__(self) -> None:
        self.timings_ms: dict[str, float] = {}
        #: time spent inside neural-network graphs, a part of the stages (see :meth:`add_network`)
        self.network_ms = 0.0

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the body of the ``with`` block as stage ``name`` (also when it raises)."""
        start = time.perf_counter()
        try:
            yield
        finally:
            elapsed = (time.perf_counter() - start) * 1000.0
            self.timings_ms[name] = self.timings_ms.get(name, 0.0) + elapsed

    def add(self, name: str, milliseconds: float) -> None:
        """Add an externally measured duration (e.g. a sub-stage timed inside another module)."""
        self.timings_ms[name] = self.timings_ms.get(name, 0.0) + float(milliseconds)

    def add_network(self, milliseconds: float) -> None:
        """Record that ``milliseconds`` of the stages already timed were spent inside a graph."""
        self.network_ms += float(milliseconds)

    @property
    def total_ms(self) -> float:
        return float(sum(self.timings_ms.values()))


def _proc_status_kib(key: str) -> int | None:
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith(key + ":"):
                    return int(line.split()[1])  # "VmHWM:   123456 kB"
    except (OSError, ValueError, IndexError):
        return None
    return None


def peak_rss_bytes() -> int:
    """Peak resident set size of this process in bytes (Linux ``VmHWM``; else ``getrusage``)."""
    kib = _proc_status_kib("VmHWM")
    if kib is not None:
        return kib * 1024
    try:
        import resource
    except ImportError:  # pragma: no cover - Windows
        return 0
    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return int(maxrss if sys.platform == "darwin" else maxrss * 1024)  # macOS reports bytes


def current_rss_bytes() -> int:
    """Current resident set size in bytes (Linux ``VmRSS``; 0 where unknown)."""
    kib = _proc_status_kib("VmRSS")
    return 0 if kib is None else kib * 1024


@dataclass(frozen=True)
class Budget:
    """What the flight computer allows the runtime.

    Attributes:
        rate_hz: required pose rate; the per-frame latency budget is ``1000 / rate_hz`` ms and is
            compared with the p95 of the total frame time.
        peak_rss_mb: peak resident memory of the whole process, MiB.
        cores: CPU cores available (the number of onnxruntime intra-op threads to profile with).
    """

    rate_hz: float = 1.0
    peak_rss_mb: float = 1536.0
    cores: int = 2

    def __post_init__(self) -> None:
        for name in ("rate_hz", "peak_rss_mb"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
                raise ValueError(f"budget {name} must be a positive number, got {value!r}")
        if isinstance(self.cores, bool) or not isinstance(self.cores, int) or self.cores < 1:
            raise ValueError(f"budget cores must be an integer >= 1, got {self.cores!r}")

    @property
    def frame_ms(self) -> float:
        """Per-frame latency budget in milliseconds."""
        return 1000.0 / self.rate_hz


#: 1 Hz, 1.5 GB peak RSS, 2 cores (a small flight computer; project assumption).
DEFAULT_BUDGET = Budget()


def _parse_flat_yaml(text: str) -> dict[str, object]:
    """``key: value`` lines (comments and an OpenCV ``%YAML`` header allowed); values are numbers."""
    out: dict[str, object] = {}
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if not line or line.startswith("%") or line == "---":
            continue
        if ":" not in line:
            raise ValueError(f"not a 'key: value' line: {raw!r}")
        key, value = (part.strip() for part in line.split(":", 1))
        try:
            out[key] = int(value)
        except ValueError:
            try:
                out[key] = float(value)
            except ValueError as err:
                raise ValueError(f"value of {key!r} is not a number: {value!r}") from err
    return out


def load_budget(path: str | os.PathLike | None = None) -> Budget:
    """Read a :class:`Budget` from JSON (``.json``) or flat YAML; ``None`` gives the default.

    Unknown keys are an error (a typo must not silently fall back to a default).

    Raises:
        FileNotFoundError: ``path`` does not exist.
        ValueError: the file is not valid JSON/YAML, has unknown keys or bad values.
    """
    if path is None:
        return DEFAULT_BUDGET
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    try:
        data = json.loads(text) if path.suffix.lower() == ".json" else _parse_flat_yaml(text)
    except json.JSONDecodeError as err:
        raise ValueError(f"budget file {path} is not valid JSON: {err}") from err
    if not isinstance(data, dict):
        raise ValueError(f"budget file {path} must hold a mapping, got {type(data).__name__}")
    known = {f.name for f in fields(Budget)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"budget file {path}: unknown keys {unknown}; valid keys: {sorted(known)}")
    if "cores" in data and isinstance(data["cores"], float) and float(data["cores"]).is_integer():
        data["cores"] = int(data["cores"])
    return Budget(**data)


def network_split(totals_ms: Sequence[float], network_ms: Sequence[float]) -> dict[str, float]:
    """Network vs pipeline time over frames: sums, and the non-network share of the total time.

    ``totals_ms[i]`` is frame i's total (sum of its stages), ``network_ms[i]`` the part of it spent
    inside graphs. ``non_network_share`` is sum(total - network) / sum(total) (time-weighted), and
    ``non_network_share_p50`` the median of the per-frame shares.
    """
    total = np.asarray(totals_ms, dtype=np.float64)
    net = np.asarray(network_ms, dtype=np.float64)
    if total.shape != net.shape or total.size == 0:
        raise ValueError("need one network time per frame total, and at least one frame")
    share = np.where(total > 0, (total - net) / np.where(total > 0, total, 1.0), 0.0)
    return {"total_ms_sum": float(total.sum()), "network_ms_sum": float(net.sum()),
            "non_network_share": float((total.sum() - net.sum()) / total.sum()) if total.sum() > 0 else 0.0,
            "non_network_share_p50": float(np.median(share)), "frames": int(total.size)}


def summarize_timings(samples: Sequence[Mapping[str, float]]) -> dict[str, dict[str, float]]:
    """Per-stage ``{"p50", "p95", "max", "mean", "n"}`` over frames, plus a ``"total"`` row.

    ``samples`` holds one ``timings_ms`` mapping per frame; a stage missing from a frame (e.g. the
    pose stage of a frame without target) is simply not counted for that frame.
    """
    per_stage: dict[str, list[float]] = {}
    totals: list[float] = []
    for timings in samples:
        for name, ms in timings.items():
            per_stage.setdefault(name, []).append(float(ms))
        totals.append(float(sum(timings.values())))
    if samples:
        per_stage["total"] = totals
    out: dict[str, dict[str, float]] = {}
    for name, values in per_stage.items():
        arr = np.asarray(values, dtype=np.float64)
        out[name] = {
            "p50": float(np.percentile(arr, 50)),
            "p95": float(np.percentile(arr, 95)),
            "max": float(arr.max()),
            "mean": float(arr.mean()),
            "n": int(arr.size),
        }
    return out


def check_budget(summary: Mapping[str, Mapping[str, float]], peak_rss: int, budget: Budget) -> list[str]:
    """Reasons the profile breaks ``budget`` (empty when within budget).

    Args:
        summary: output of :func:`summarize_timings` (its ``"total"`` p95 is compared with
            ``budget.frame_ms``).
        peak_rss: peak resident set size in bytes.
        budget: the limits.
    """
    problems: list[str] = []
    total = summary.get("total")
    if total is not None and total["p95"] > budget.frame_ms:
        problems.append(f"p95 frame time {total['p95']:.0f} ms exceeds {budget.frame_ms:.0f} ms "
                        f"({budget.rate_hz:g} Hz)")
    rss_mb = peak_rss / 2**20
    if rss_mb > budget.peak_rss_mb:
        problems.append(f"peak RSS {rss_mb:.0f} MiB exceeds {budget.peak_rss_mb:.0f} MiB")
    return problems


def budget_to_dict(budget: Budget) -> dict[str, object]:
    """JSON-serialisable form of ``budget`` (plus the derived ``frame_ms``)."""
    return {**asdict(budget), "frame_ms": budget.frame_ms}
