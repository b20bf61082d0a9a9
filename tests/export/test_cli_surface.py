"""Tests of ``spacepose export-surface``: surface samples + normals and the registration section."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("trimesh")

from spacepose.bundle import load_bundle  # noqa: E402
from spacepose.cli import main  # noqa: E402
from spacepose.errors import BundleError  # noqa: E402

DEFAULT = Path(__file__).resolve().parents[2] / "runtime" / "bundles" / "default"


@pytest.fixture()
def bundle_copy(tmp_path):
    folder = tmp_path / "bundle"
    folder.mkdir()
    for name in ("bundle.json", "MODEL_CARD.md"):
        shutil.copyfile(DEFAULT / name, folder / name)
    for name in ("stereo.onnx", "pose.onnx", "flip.onnx", "outline.onnx"):  # graphs only read for metadata: link them
        (folder / name).symlink_to(DEFAULT / name)
    return folder


def _drop_flip_classifier(folder: Path) -> None:
    """The bundle without its flip classifier and outline refiner sections (which need the silhouette stage)."""
    data = json.loads((folder / "bundle.json").read_text())
    data.pop("flip_classifier", None)
    data.pop("outline_refiner", None)
    (folder / "bundle.json").write_text(json.dumps(data, indent=1))


def test_writes_samples_on_the_mesh_with_unit_normals(bundle_copy):
    from spacepose.tools.targets import load_target

    assert main(["export-surface", str(bundle_copy), "--count", "500", "--seed", "3",
                 "--registration", "min_margin=0.07", "starts=24", "--flip-axis", "z"]) == 0
    b = load_bundle(bundle_copy)
    assert b.surface_points.shape == (500, 3) and b.surface_normals.shape == (500, 3)
    np.testing.assert_allclose(np.linalg.norm(b.surface_normals, axis=1), 1.0, atol=1e-4)
    assert b.registration.min_margin == 0.07 and b.registration.starts == 24 and b.voting.flip_axis == "z"
    # the samples are trimesh's seeded area-uniform draw, each with the normal of the face it lies on
    import trimesh

    mesh = load_target(b.target_name).mesh
    points, faces = trimesh.sample.sample_surface(mesh, 500, seed=3)
    np.testing.assert_allclose(b.surface_points, points, atol=1e-4)
    np.testing.assert_allclose(b.surface_normals, mesh.face_normals[faces], atol=1e-4)
    # on the face's plane: (p - vertex) . n = 0
    offset = np.einsum("ij,ij->i", b.surface_points - mesh.triangles[faces][:, 0], mesh.face_normals[faces])
    assert np.abs(offset).max() < 1e-3
    # the other sections are untouched
    before = json.loads((DEFAULT / "bundle.json").read_text())
    after = json.loads((bundle_copy / "bundle.json").read_text())
    assert after["stereo"] == before["stereo"] and after["pose"] == before["pose"]
    # the silhouette stage decides between registered poses: it cannot stay without the registration
    assert main(["export-surface", str(bundle_copy), "--count", "500", "--no-registration"]) == 2
    # ... nor the shipped flip classifier without the silhouette stage: refused, the bundle kept as it was
    text = (bundle_copy / "bundle.json").read_text()
    assert main(["export-surface", str(bundle_copy), "--count", "500", "--no-registration", "--no-silhouette"]) == 2
    assert (bundle_copy / "bundle.json").read_text() == text
    _drop_flip_classifier(bundle_copy)
    # ... nor the shipped uncertainty sections without the registration (its depth tolerance scales the range)
    text = (bundle_copy / "bundle.json").read_text()
    assert main(["export-surface", str(bundle_copy), "--count", "500", "--no-registration", "--no-silhouette"]) == 2
    assert (bundle_copy / "bundle.json").read_text() == text
    data = json.loads(text)
    assert data.pop("uncertainty") and data.pop("position_uncertainty")
    data.pop("confidence", None)   # computed from the uncertainty section: it goes with it
    (bundle_copy / "bundle.json").write_text(json.dumps(data, indent=1))
    assert main(["export-surface", str(bundle_copy), "--count", "500", "--no-registration", "--no-silhouette"]) == 0
    assert load_bundle(bundle_copy).registration is None


def test_a_bad_registration_key_leaves_the_bundle_as_it_was(bundle_copy, capsys):
    text = (bundle_copy / "bundle.json").read_text()
    assert main(["export-surface", str(bundle_copy), "--count", "100", "--registration", "stars=3"]) == 2
    assert "unknown keys in registration" in capsys.readouterr().err
    assert (bundle_copy / "bundle.json").read_text() == text
    with pytest.raises(BundleError):  # the same through the function, for a caller that wants the error
        from spacepose.bundle import load_bundle as _load

        (bundle_copy / "bundle.json").write_text(text.replace('"registration": {', '"registration": {"stars": 3, '))
        _load(bundle_copy)


@pytest.mark.parametrize("argv", [["--registration", "min_margin"], ["--registration", "min_margin=x"],
                                  ["--count", "5"], ["--registration", "--no-registration"]])
def test_bad_arguments_are_refused(bundle_copy, argv):
    text = (bundle_copy / "bundle.json").read_text()
    with pytest.raises(SystemExit):
        main(["export-surface", str(bundle_copy), *argv])
    assert (bundle_copy / "bundle.json").read_text() == text


def test_writes_outline_samples_and_the_silhouette_section(bundle_copy):
    from spacepose.tools.targets import load_target

    # --silhouette writes the section from the keys given: without polish the shipped outline refiner cannot load,
    # so the call is refused and the bundle kept as it was
    text = (bundle_copy / "bundle.json").read_text()
    args = ["export-surface", str(bundle_copy), "--count", "300", "--silhouette-count", "2000",
            "--silhouette", "max_chamfer_px=1.5", "min_margin_px=0.25"]
    assert main(args) == 2 and (bundle_copy / "bundle.json").read_text() == text
    data = json.loads(text)
    data.pop("outline_refiner")
    (bundle_copy / "bundle.json").write_text(json.dumps(data, indent=1))
    assert main(args) == 0
    b = load_bundle(bundle_copy)
    assert b.silhouette_points.shape == (2000, 3)
    assert b.silhouette.max_chamfer_px == 1.5 and b.silhouette.min_margin_px == 0.25
    # trimesh's seeded area-uniform draw (seed + 1, rounded to the mm), not the surface samples again
    import trimesh

    points, _ = trimesh.sample.sample_surface(load_target(b.target_name).mesh, 2000, seed=1)
    np.testing.assert_allclose(b.silhouette_points, points, atol=6e-4)
    assert not np.allclose(b.silhouette_points[:300], b.surface_points[:300])
    # a later call that does not name them keeps the samples and the section
    assert main(["export-surface", str(bundle_copy), "--count", "300"]) == 0
    assert load_bundle(bundle_copy).silhouette_points.shape == (2000, 3)
    assert main(["export-surface", str(bundle_copy), "--count", "300", "--no-silhouette"]) == 2  # the classifier needs it
    _drop_flip_classifier(bundle_copy)
    assert main(["export-surface", str(bundle_copy), "--count", "300", "--no-silhouette"]) == 0
    b = load_bundle(bundle_copy)
    assert b.silhouette is None and b.silhouette_points.shape == (0, 3)


@pytest.mark.parametrize("argv", [["--silhouette-count", "50"], ["--no-silhouette", "--silhouette-count", "500"],
                                  ["--silhouette", "max_chamfer_px=-1"], ["--no-registration", "--silhouette"]])
def test_bad_silhouette_arguments_leave_the_bundle_as_it_was(bundle_copy, argv):
    text = (bundle_copy / "bundle.json").read_text()
    try:
        code = main(["export-surface", str(bundle_copy), "--count", "100", *argv])
    except (SystemExit, BundleError):
        code = None
    assert code != 0
    assert (bundle_copy / "bundle.json").read_text() == text
