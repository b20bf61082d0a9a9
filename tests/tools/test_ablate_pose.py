"""ablate_pose Table 6 helpers: MAC counting grows faster for vanilla attention than for ECAA."""

import pytest

pytest.importorskip("torch")

from spacepose.tools.ablate_pose import cost_table, count_macs  # noqa: E402

NET = {"n_levels": 2, "k": 8, "rgb_widths": [16, 16], "point_widths": [16, 16], "rgb_stem": 8, "point_stem": 8}


def test_macs_positive_and_vanilla_grows_faster():
    rows = cost_table([(128, 64), (512, 128)], NET, memory=False)
    by = {(r["attention"], r["n_points"]): r["gmacs"] for r in rows}
    assert all(v > 0 for v in by.values())
    growth_ecaa = by[("ecaa", 512)] / by[("ecaa", 128)]
    growth_vanilla = by[("vanilla", 512)] / by[("vanilla", 128)]
    assert growth_vanilla > growth_ecaa
    assert count_macs({**NET, "n_points": 128, "crop_size": [64, 64]})["params_m"] > 0
