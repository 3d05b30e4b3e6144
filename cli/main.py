"""The ``mocap-exaggerate`` command line: parses options, calls the library, reports.

No algorithm lives here. One module per command (`exaggerate`, `batch`, `plan`, `info`,
`preview`, `compare`, `tune`, `presets`), each registering itself on the group in `app` when imported; the
options they share are in `options`. ``mocap-exaggerate`` runs `main`.
"""

from __future__ import annotations

import sys

from . import batch, compare, exaggerate, info, plan, presets, preview, tune  # noqa: F401  (each registers its command)
from .app import cli

__all__ = ["cli", "main"]


def main() -> None:
    code = cli.main(prog_name="mocap-exaggerate")
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
