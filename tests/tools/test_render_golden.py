"""The renderer against frames stored from an earlier machine (cross-machine reproducibility).

The evaluation sets are rendered again on each session's machine, and session 29 found 1-2 % of frames
changing their validity between machines without knowing whether the renderer or onnxruntime moved.
These frames were rendered once and stored (``data/render_golden.npz``); on any machine the renderer must
give them back: the poses exactly (they come from the generator alone), the images and masks up to the
edge pixels a ray caster built for another instruction set may flip. Whether they came back bit for bit
shows in the summary line: ``test_bit_identical`` is an expected failure that passes (xpassed) when they did.

Regenerate the file only for an intended change of the renderer::

    python tests/tools/test_render_golden.py --write
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import numpy as np
import pytest

GOLDEN = Path(__file__).with_name("data") / "render_golden.npz"
SIZE = (160, 120)
SEED = 31
REGIMES = ("sun", "mixed")

log = logging.getLogger(__name__)


def render_golden() -> dict[str, np.ndarray]:
    """The stored frames, rendered now: per frame ``k`` the uint8 views ``left{k}``, ``right{k}``, the left
    ``mask{k}``, the float32 ``disparity{k}`` and the float64 pose ``R{k}``, ``t{k}``."""
    from spacepose.calibration.rig import paper_rig
    from spacepose.tools.degrade import to_uint8
    from spacepose.tools.render import PoseSampler, StereoCamera, render_stereo, sample_scene
    from spacepose.tools.targets import load_target

    camera = StereoCamera.from_rig(paper_rig(*SIZE))
    target = load_target("tdrs")
    sampler = PoseSampler(camera, target.bounding_radius, (10.0, 11.0))
    out: dict[str, np.ndarray] = {}
    for k, regime in enumerate(REGIMES):
        scene = sample_scene(target, camera, np.random.default_rng([SEED, k]), regime, sampler)
        frame = render_stereo(target, camera, scene)
        out.update({f"left{k}": to_uint8(frame.left), f"right{k}": to_uint8(frame.right), f"mask{k}": frame.mask,
                    f"disparity{k}": frame.disparity.astype(np.float32),
                    f"R{k}": np.asarray(scene.R, dtype=np.float64), f"t{k}": np.asarray(scene.t, dtype=np.float64)})
    return out


@pytest.fixture(scope="module")
def frames():
    pytest.importorskip("embreex")
    if not GOLDEN.exists():
        pytest.fail(f"{GOLDEN} is missing: run `python {Path(__file__).name} --write` for an intended renderer change")
    with np.load(GOLDEN) as stored:
        return dict(stored), render_golden()


def test_same_keys(frames):
    stored, now = frames
    assert sorted(stored) == sorted(now)


@pytest.mark.parametrize("k", range(len(REGIMES)))
def test_pose_exact(frames, k):
    stored, now = frames
    np.testing.assert_array_equal(now[f"R{k}"], stored[f"R{k}"])
    np.testing.assert_array_equal(now[f"t{k}"], stored[f"t{k}"])


@pytest.mark.parametrize("k", range(len(REGIMES)))
def test_target_in_view(frames, k):
    """A golden frame that shows little of the target would test little."""
    stored, _ = frames
    assert stored[f"mask{k}"].mean() > 0.03


@pytest.mark.parametrize("k", range(len(REGIMES)))
def test_images_match(frames, k):
    """Mean difference under 0.5 DN and at most 1 % of pixels off by more than 8 DN (edge flips)."""
    stored, now = frames
    exact = True
    for view in ("left", "right"):
        a, b = stored[f"{view}{k}"].astype(np.int16), now[f"{view}{k}"].astype(np.int16)
        assert a.shape == b.shape
        diff = np.abs(a - b)
        exact &= not diff.any()
        assert diff.mean() < 0.5, f"{view}{k}: mean |difference| {diff.mean():.3f} DN"
        assert (diff.max(axis=-1) > 8).mean() <= 0.01, f"{view}{k}: {(diff.max(axis=-1) > 8).mean():.2%} pixels off"
    log.info("golden frame %d: images %s", k, "bit-identical" if exact else "within tolerance, not bit-identical")


@pytest.mark.xfail(strict=False, reason="a ray caster built for another instruction set may flip edge pixels; "
                   "the summary's xpassed / xfailed count tells whether this machine renders bit for bit")
def test_bit_identical(frames):
    stored, now = frames
    for key, value in stored.items():
        np.testing.assert_array_equal(now[key], value, err_msg=key)


@pytest.mark.parametrize("k", range(len(REGIMES)))
def test_mask_and_disparity_match(frames, k):
    """The mask up to 1 % of its pixels; the disparity on pixels both masks hold to 1e-3 px."""
    stored, now = frames
    a, b = stored[f"mask{k}"], now[f"mask{k}"]
    assert (a ^ b).sum() <= 0.01 * a.sum()
    both = a & b
    np.testing.assert_allclose(now[f"disparity{k}"][both], stored[f"disparity{k}"][both], atol=1e-3)


if __name__ == "__main__":
    if sys.argv[1:] != ["--write"]:
        raise SystemExit(f"usage: python {sys.argv[0]} --write   (overwrites {GOLDEN})")
    GOLDEN.parent.mkdir(exist_ok=True)
    np.savez_compressed(GOLDEN, **render_golden())
    print(f"wrote {GOLDEN} ({GOLDEN.stat().st_size / 1024:.0f} KiB)")
