"""``spacepose export-surface BUNDLE``: (re)write a bundle's target surface samples and their normals.

The runtime's surface checks and :mod:`spacepose.registration` read ``target.surface_points`` and
``target.surface_normals`` from ``bundle.json``; this samples them from the target mesh
(:func:`spacepose.export.onnx_pose.target_geometry`, area-uniform, seeded) without touching the
graphs or any other section. ``--registration KEY=VALUE ...`` also sets the ``registration``
section (e.g. ``min_margin=0.05`` from ``python -m spacepose.tools.calibrate_gates``), and
``--flip-axis`` the target's near-symmetry axis (``voting.flip_axis``). ``--silhouette-count N``
writes ``target.silhouette_points`` (the outline samples of :mod:`spacepose.silhouette`) and
``--silhouette KEY=VALUE ...`` its ``silhouette`` section; ``--no-silhouette`` removes both.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path

HELP = "write a bundle's target surface samples + normals (optionally its registration and silhouette sections)"

log = logging.getLogger(__name__)


def _key_value(text: str) -> tuple[str, float | int]:
    key, sep, value = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    try:
        number = json.loads(value)
    except json.JSONDecodeError as err:
        raise argparse.ArgumentTypeError(f"{key}: {value!r} is not a number") from err
    if isinstance(number, bool) or not isinstance(number, (int, float)):
        raise argparse.ArgumentTypeError(f"{key}: {value!r} is not a number")
    return key, number


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("bundle", type=Path, help="bundle folder (its bundle.json is updated in place)")
    parser.add_argument("--count", type=int, default=6000, help="surface samples")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--registration", type=_key_value, nargs="*", default=None, metavar="KEY=VALUE",
                        help="set the registration section (RegistrationConfig fields; none given: defaults)")
    parser.add_argument("--no-registration", action="store_true", help="remove the registration section")
    parser.add_argument("--flip-axis", choices=["", "x", "y", "z"], default=None, help="set voting.flip_axis")
    parser.add_argument("--silhouette-count", type=int, default=None,
                        help="write this many outline samples (target.silhouette_points); default: keep")
    parser.add_argument("--silhouette", type=_key_value, nargs="*", default=None, metavar="KEY=VALUE",
                        help="set the silhouette section (SilhouetteConfig fields; none given: defaults)")
    parser.add_argument("--no-silhouette", action="store_true", help="remove the silhouette section and samples")


def run(args: argparse.Namespace) -> int:
    from spacepose._optional import import_optional

    import_optional("trimesh")
    from spacepose.bundle import load_bundle
    from spacepose.errors import BundleError
    from spacepose.export.onnx_common import update_manifest
    from spacepose.export.onnx_pose import target_geometry

    if args.count < 12:
        raise SystemExit("--count must be >= 12")
    if args.registration is not None and args.no_registration:
        raise SystemExit("--registration and --no-registration exclude each other")
    if args.no_silhouette and (args.silhouette is not None or args.silhouette_count is not None):
        raise SystemExit("--no-silhouette excludes --silhouette and --silhouette-count")
    if args.silhouette_count is not None and args.silhouette_count < 100:
        raise SystemExit("--silhouette-count must be >= 100")
    bundle = load_bundle(args.bundle)  # refuses a broken bundle before anything is written
    geometry = target_geometry(bundle.target_name, bundle.centre, n_surface=args.count, seed=args.seed,
                               n_silhouette=args.silhouette_count or 0)
    backup = (args.bundle / "bundle.json").read_text(encoding="utf-8")

    def update(data: dict) -> None:
        target = data["target"]
        target["surface_points"] = geometry["surface_points"]
        target["surface_normals"] = geometry["surface_normals"]
        if args.registration is not None:
            data["registration"] = dict(args.registration)
        if args.no_registration:
            data.pop("registration", None)
        if args.flip_axis is not None:
            data.setdefault("voting", {})["flip_axis"] = args.flip_axis
        if "silhouette_points" in geometry:
            target["silhouette_points"] = geometry["silhouette_points"]
        if args.silhouette is not None:
            data["silhouette"] = dict(args.silhouette)
        if args.no_silhouette:
            data.pop("silhouette", None)
            target.pop("silhouette_points", None)

    path = update_manifest(args.bundle, update)
    try:
        load_bundle(args.bundle)
    except BundleError:
        (args.bundle / "bundle.json").write_text(backup, encoding="utf-8")  # keep what the user had
        raise
    log.info("wrote %d surface samples with normals to %s", args.count, path)
    print(f"{path}: {args.count} surface samples + normals (seed {args.seed})"
          + (f", registration {dict(args.registration)}" if args.registration is not None else "")
          + (f", {args.silhouette_count} outline samples" if args.silhouette_count else "")
          + (f", silhouette {dict(args.silhouette)}" if args.silhouette is not None else ""))
    return 0
