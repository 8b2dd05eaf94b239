"""`ecodrive <command>`: the project's commands by name, each dispatched to the module that implements it.

Commands: ``study`` (the paper's study), ``score`` (same as ``replay``: score a trace), ``serve``, ``corridor``
(corridor and plan files: ``from-osm``, ``show``, ``tables``, ``schema``), ``spat-eval`` (the advisor
on a recorded SPaT log), ``predict-eval``, ``traffic-eval`` (the advisor among other cars in Eclipse SUMO).
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

COMMANDS = {
    "study": "ecodrive.study",
    "score": "replay.cli",
    "serve": "server.main",
    "corridor": "ecodrive.corridor",
    "spat-eval": "ecodrive.spat_eval",
    "predict-eval": "ecodrive.predict_eval",
    "traffic-eval": "ecodrive.traffic_eval",
}


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in COMMANDS:
        known = ", ".join(COMMANDS)
        print(f"usage: ecodrive {{{known}}} [options]   (ecodrive <command> --help for more)", file=sys.stderr if argv else sys.stdout)
        return 0 if not argv or argv[0] in ("-h", "--help") else 2
    import importlib

    return importlib.import_module(COMMANDS[argv[0]]).main(argv[1:])


if __name__ == "__main__":
    sys.exit(main())
