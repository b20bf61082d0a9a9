"""Tests of ``spacepose calibrate`` (spacepose.calibration.cli_calibrate) through the CLI entry point."""

from __future__ import annotations

import argparse

import pytest

from spacepose.calibration import cli_calibrate
from spacepose.calibration.rig import load_rig, paper_rig, save_rig
from spacepose.cli import main


def calibrate(folder, out, *extra):
    return main(["calibrate", str(folder), "--board", "9x6", "--square", "0.03", "--out", str(out), *extra])


def test_writes_rig_and_prints_rms(board_scene, tmp_path, capsys):
    out = tmp_path / "rig.yaml"
    assert calibrate(board_scene.folder, out) == 0
    printed = capsys.readouterr().out
    assert "RMS reprojection" in printed and "px" in printed and str(out) in printed
    rig = load_rig(out)
    assert rig.image_size == (640, 480)
    assert rig.M1[0, 0] == pytest.approx(board_scene.rig.M1[0, 0], rel=0.005)
    assert rig.baseline_m == pytest.approx(board_scene.rig.baseline_m, rel=0.005)


def test_refuses_to_overwrite_without_force(board_scene, tmp_path, capsys):
    out = tmp_path / "rig.json"
    save_rig(paper_rig(), out)
    assert calibrate(board_scene.folder, out) == 2
    assert "--force" in capsys.readouterr().err
    assert load_rig(out) == paper_rig()
    assert calibrate(board_scene.folder, out, "--force") == 0
    assert load_rig(out).image_size == (640, 480)


def test_folder_without_pairs_is_an_error(tmp_path, capsys):
    (tmp_path / "left").mkdir()
    (tmp_path / "right").mkdir()
    assert calibrate(tmp_path, tmp_path / "rig.yaml") == 2
    assert "need at least 3" in capsys.readouterr().err
    assert not (tmp_path / "rig.yaml").exists()
    assert calibrate(tmp_path / "missing", tmp_path / "rig.yaml") == 2


def test_bad_extension(board_scene, tmp_path, capsys):
    assert calibrate(board_scene.folder, tmp_path / "rig.txt") == 2
    assert ".yaml" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv",
    [
        ["--board", "9by6", "--square", "0.03"],
        ["--board", "2x6", "--square", "0.03"],
        ["--board", "9x6", "--square", "-1"],
        ["--board", "9x6", "--square", "wide"],
        ["--board", "9x6"],  # --square is required
    ],
)
def test_bad_arguments_exit_2(tmp_path, argv):
    with pytest.raises(SystemExit) as info:
        main(["calibrate", str(tmp_path), "--out", str(tmp_path / "rig.yaml"), *argv])
    assert info.value.code == 2


def test_module_interface():
    assert isinstance(cli_calibrate.HELP, str) and cli_calibrate.HELP
    parser = argparse.ArgumentParser()
    cli_calibrate.add_arguments(parser)
    args = parser.parse_args(["folder", "--square", "0.025", "--out", "r.yaml"])
    assert args.board == (9, 6) and args.square == 0.025 and not args.force
