"""flip_relief: a shape symmetric under the flip is not moved by it; an asymmetric part is, by its offset."""

import numpy as np
import pytest

pytest.importorskip("scipy")

from spacepose.tools.flip_relief import flip_relief  # noqa: E402


def _grid_box(half, step=0.05, offset=(0, 0, 0)):
    axes = [np.arange(-h, h + 1e-9, step) for h in half]
    g = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    return g + np.asarray(offset)


def test_symmetric_box_is_not_moved_and_a_lump_is():
    box = _grid_box((1.0, 0.5, 0.25))
    np.testing.assert_allclose(flip_relief(box, np.zeros(3), "z"), 0.0, atol=1e-9)
    lump = _grid_box((0.1, 0.1, 0.1), offset=(0.6, 0.0, 0.5))           # sticks out above +x only
    d = flip_relief(np.vstack([box, lump]), np.zeros(3), "z")
    moved = d > 0.05
    assert 0 < moved.mean() < 0.1                                       # only the lump's image moves
    assert d.max() == pytest.approx(0.5 + 0.1 - 0.25, abs=1e-6)        # its top, 0.35 m above the box
    # the turn about x puts the lump below the box instead: moved as far
    assert flip_relief(np.vstack([box, lump]), np.zeros(3), "x").max() == pytest.approx(0.35, abs=1e-6)
