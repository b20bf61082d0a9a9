"""Session 41, exploratory: the outline refiner's samples (since then ``python -m spacepose.tools.outline_data``).

    python reports/outline_s41/samples.py DATASET --split train --skip S --limit N --out OUT.npz

The exploration made its sample files with this script before the product tool existed; the two made the same
arrays (checked on 20 frames), and this script now calls the tool's :func:`make_outline_samples` (the exploration's
files also held each frame's stereo window, which nothing read).
"""
from __future__ import annotations

import sys

if __name__ == "__main__":
    from spacepose.tools.outline_data import main

    sys.exit(main(sys.argv[1:]))
