"""outline_oracle: the counting, the recording of the outline stage's fits, the CLI's refusals."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "runtime"))  # the silhouette test helpers
from test_silhouette import CENTRE, K, _disparity_of, _pose, _slab  # noqa: E402

from spacepose.flip import flipped_pose  # noqa: E402
from spacepose.registration import SurfaceModel  # noqa: E402
from spacepose.silhouette import SilhouetteConfig  # noqa: E402
from spacepose.tools import outline_oracle  # noqa: E402


def _fit(chamfer, points, e_r, e_t=0.1):
    return {"chamfer_px": chamfer, "points_res": points, "e_R": e_r, "e_t": e_t}


def test_summarise_counts_outcomes_and_rankings():
    frames = [
        # the chamfer picks a flip, the points the truth; the refined truth fits better than the flip
        {"fits": [_fit(0.9, 0.2, 2.0), _fit(0.8, 1.0, 178.0)], "truth_chamfer_px": 0.7, "truth_flip_chamfer_px": 0.9},
        # the chamfer picks a wrong pose, nothing right among the fits, the truth fits worse
        {"fits": [_fit(1.0, 0.5, 40.0), _fit(1.5, 0.4, 170.0)], "truth_chamfer_px": 1.2, "truth_flip_chamfer_px": 1.3},
        # right by the chamfer, but too far off in range to count as right
        {"fits": [_fit(0.5, 0.1, 3.0, e_t=0.8)], "truth_chamfer_px": 0.4, "truth_flip_chamfer_px": 1.0},
        {"fits": []},                                                        # no outline stage
    ]
    s = outline_oracle.summarise(frames)
    assert s["frames"] == 4 and s["with_outline"] == 3 and s["any_right"] == 1
    assert s["best_by_chamfer"] == {"right": 0, "flip": 1, "wrong": 2}
    assert s["truth_fits_better"] == {"right": 0, "flip": 1, "wrong": 1}
    assert s["ranked_by_chamfer_plus_w_points"]["0.0"] == {"right": 0, "flip": 1, "wrong": 2}
    assert s["ranked_by_chamfer_plus_w_points"]["1.0"] == {"right": 1, "flip": 0, "wrong": 2}
    assert outline_oracle.summarise(frames, max_e_t=1.0)["best_by_chamfer"]["right"] == 1


def test_recording_keeps_the_decisions_fits_and_restores_the_stage():
    import spacepose.estimator as est
    import spacepose.silhouette as sil

    rng = np.random.default_rng(0)
    pts, nrm = _slab((-2, -1, -0.2), (2, 1, 0.2), 2000, rng)
    tab, tab_n = _slab((2, 0.1, -0.2), (3, 0.9, 0.2), 2000, rng)
    pts, nrm = np.vstack([pts, tab]), np.vstack([nrm, tab_n])
    R, t = _pose()
    disp = _disparity_of(pts, R, t)
    cam = pts @ R.T + t
    stereo = cam[np.einsum("ij,ij->i", nrm @ R.T, cam) < 0][::10]
    surface = SurfaceModel(pts, nrm)
    before = (est.decide_outline, sil.refine_outline)
    store = []
    with outline_oracle._recording(store) as decisions:
        dec = est.decide_outline([(R, t)], pts, disp, K, 1.0, (160, 80, 320), SilhouetteConfig(iterations=4),
                                 stereo_points=stereo, surface=surface, tau_m=0.2,
                                 flip=lambda R_, t_: flipped_pose(R_, t_, CENTRE, "z"))
        sil.refine_outline(R, t, pts, dec.observed, dec.frame)          # outside a decision: not recorded
    assert (est.decide_outline, sil.refine_outline) == before
    assert len(decisions) == 1 and decisions[0]["result"] is dec
    assert len(store) == 2                                               # the candidate and the flip of the best
    fit, P, surf, tau = store[0]
    assert surf is surface and tau == 0.2
    res = outline_oracle._points_res(fit, P, surf, tau)
    assert 0.0 <= res < 0.5                                              # the stereo points lie on the surface
    flipped = outline_oracle._points_res(store[1][0], P, surf, tau)
    assert res < flipped <= 3.0
    assert np.isnan(outline_oracle._points_res(fit, None, surf, tau))


def test_cli_refuses_the_test_split_and_an_existing_report(tmp_path):
    with pytest.raises(SystemExit, match="not the test split"):
        outline_oracle.main(["data", "--bundle", "b", "--split", "test", "--out", str(tmp_path / "o.json")])
    (tmp_path / "o.json").write_text("{}")
    with pytest.raises(SystemExit, match="exists"):
        outline_oracle.main(["data", "--bundle", "b", "--out", str(tmp_path / "o.json")])
    assert (tmp_path / "o.json").read_text() == "{}"
