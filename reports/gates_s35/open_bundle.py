"""Write session 35's open bundle: the default bundle with the outline, image-route and classifier gates open, the
registration's margin closed and no confidence floor (reports/gates_s35/rule.txt).

    python reports/gates_s35/open_bundle.py OUT_DIR        # e.g. /tmp/s35/bundles/open

Since session 37 the values live in ``spacepose.tools.open_gates`` (``OPEN_GATES``, the same ones), which also
takes any other bundle: ``python -m spacepose.tools.open_gates SRC DST``.
"""
from __future__ import annotations

import sys
from pathlib import Path

from spacepose.errors import BundleError
from spacepose.tools.open_gates import write_open_bundle

DEFAULT = Path(__file__).resolve().parents[2] / "runtime" / "bundles" / "default"


def main(argv: list[str]) -> int:
    try:
        write_open_bundle(DEFAULT, Path(argv[0]))
    except BundleError as exc:
        raise SystemExit(str(exc)) from exc
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
