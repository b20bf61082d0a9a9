"""`spacepose demo` (the README's main command) runs end to end with the shipped bundle."""

import re

import pytest

pytest.importorskip("trimesh")

from spacepose.cli import main  # noqa: E402


def test_demo_renders_estimates_and_summarises(capsys):
    assert main(["demo", "--count", "2", "--threads", "1"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if re.match(r"^00000[01]\s", line)]
    assert len(rows) == 2 and all(("True" in r) or ("False" in r) for r in rows)
    assert re.search(r"^summary: [0-2]/2 valid", out, re.M)
    m = re.search(r"^target position \(with or without the attitude\): ([0-2])/2", out, re.M)
    assert m is not None
    # every valid pose has its position, so there are at least as many positions as valid poses
    valid = int(re.search(r"^summary: ([0-2])/2 valid", out, re.M).group(1))
    assert int(m.group(1)) >= valid
