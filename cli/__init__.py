"""The command-line application (click), kept apart from the library."""

import _signal  # the C module: `signal` itself takes milliseconds to import (its enums), a window of its own
import os as _os
import sys as _sys


def _aborted(signum, frame) -> None:  # pragma: no cover - runs in a process ending at once
    _sys.stderr.write("Aborted!\n")
    _sys.stderr.flush()
    _os._exit(130)


# Started as the command (``mocap-exaggerate`` or ``python -m mocap_exaggerate_cli.main``, whose argv[0] is
# "-m" while Python finds the module), a Ctrl-C between here and `main.main` taking over ends it quietly, as
# one in `main` does, not with a traceback from the middle of an import. Imported any other way (a test, a
# program embedding the group), the process's Ctrl-C is left alone. Before this line runs, Python is still
# starting: a Ctrl-C then is Python's own.
if (_sys.argv[:1] == ["-m"] or _os.path.basename(_sys.argv[0] if _sys.argv else "") == "mocap-exaggerate") \
        and _signal.getsignal(_signal.SIGINT) is _signal.default_int_handler:
    _signal.signal(_signal.SIGINT, _aborted)


def ctrl_c_as_usual() -> None:
    """Python's own Ctrl-C (KeyboardInterrupt) back where the quiet exit above was set."""
    if _signal.getsignal(_signal.SIGINT) is _aborted:
        _signal.signal(_signal.SIGINT, _signal.default_int_handler)
