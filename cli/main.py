"""The ``mocap-exaggerate`` command line: parses options, calls the library, reports.

No algorithm lives here. One module per command (`exaggerate`, `batch`, `plan`, `info`,
`preview`, `compare`, `tune`, `presets`), each registering itself on the group in `app` when imported; the
options they share are in `options`. ``mocap-exaggerate`` runs `main`.

The commands are imported inside `main`, under its Ctrl-C handling: one pressed in the first tenths of a
second (while click and NumPy load) ends the command quietly (exit 130) instead of printing a traceback.
"""

from __future__ import annotations

import sys

__all__ = ["cli", "main"]  # noqa: F822  (cli: the group, made on first use by __getattr__)


def _group():
    from . import batch, compare, exaggerate, info, plan, presets, preview, tune  # noqa: F401  (each registers its command)
    from .app import cli

    return cli


def main() -> None:
    from . import ctrl_c_as_usual

    try:
        ctrl_c_as_usual()  # (a Ctrl-C while the command loaded ended it quietly; from here it is ours to handle)
        from mocap_exaggerate.jobs.memory import keep_freed_memory

        keep_freed_memory()  # one command per process: a long clip's temporaries reuse the heap's pages
        group = _group()
        code = group.main(prog_name="mocap-exaggerate")
    except KeyboardInterrupt:  # before the group's own handling took over (while loading)
        sys.stderr.write("Aborted!\n")
        code = 130
    except RuntimeError as error:  # Python wraps one pressed while a dataclass is being made
        if not isinstance(error.__cause__, KeyboardInterrupt):
            raise
        sys.stderr.write("Aborted!\n")
        code = 130
    sys.exit(code if isinstance(code, int) else 0)


def __getattr__(name: str):
    if name == "cli":  # the click group, for tests and embedding (``from mocap_exaggerate_cli.main import cli``)
        return _group()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


if __name__ == "__main__":
    main()
