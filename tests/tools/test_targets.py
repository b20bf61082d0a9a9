"""Target loading: the 5.0 m rule, part labels, bad input."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from spacepose.errors import DatasetError
from spacepose.tools.targets import LONGEST_EXTENT_M, MESH_DIR, SHIPPED_TARGETS, TargetError, load_target


class TestLoadTarget:
    @pytest.mark.parametrize("name", sorted(SHIPPED_TARGETS))
    def test_longest_extent_is_5m(self, name):
        target = load_target(name)
        assert np.max(target.mesh.extents) == pytest.approx(LONGEST_EXTENT_M, abs=1e-9)
        assert target.name == name
        assert target.part_labels.shape == (len(target.mesh.faces),)
        assert target.n_parts == int(target.part_labels.max()) + 1 > 50
        assert target.bounding_radius == pytest.approx(np.linalg.norm(target.mesh.vertices, axis=1).max())
        assert len(target.sha256) == 64

    def test_tdrs_matches_conventions(self):
        target = load_target("tdrs")
        assert target.scale == pytest.approx(0.0473501498, rel=1e-8)
        lo, hi = target.mesh.bounds
        np.testing.assert_allclose(lo, [-2.5, -1.55, -0.33], atol=0.01)
        np.testing.assert_allclose(hi, [2.5, 1.55, 1.03], atol=0.01)
        assert target.n_parts == 331

    def test_loads_by_path(self, tmp_path):
        path = tmp_path / "copy.stl"
        shutil.copy(MESH_DIR / SHIPPED_TARGETS["mro"], path)
        target = load_target(path)
        assert target.name == "copy"
        assert target.sha256 == load_target("mro").sha256
        assert np.max(target.mesh.extents) == pytest.approx(5.0)

    def test_shipped_files_carry_licence_and_source(self):
        assert (MESH_DIR / "LICENSE_NASA.txt").is_file()
        for rel in SHIPPED_TARGETS.values():
            assert (MESH_DIR / rel).parent.joinpath("SOURCE.txt").is_file()


class TestBadInput:
    def test_unknown_name(self):
        with pytest.raises(TargetError, match="unknown target"):
            load_target("hubble")

    def test_missing_file(self, tmp_path):
        with pytest.raises(TargetError, match="not found"):
            load_target(tmp_path / "nope.stl")

    @pytest.mark.parametrize("content", [b"", b"solid x\nthis is not an stl\n", b"\x00" * 83])
    def test_corrupt_file(self, tmp_path, content):
        path = tmp_path / "bad.stl"
        path.write_bytes(content)
        with pytest.raises(TargetError):
            load_target(path)

    def test_is_a_dataset_error(self):
        assert issubclass(TargetError, DatasetError)
