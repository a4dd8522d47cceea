"""The `cdm` command of the cdm-haptics wheel.

The wheel carries the command itself as cdm/bin/cdm (the same program as the
.deb's /usr/bin/cdm, without the DDS bridge). This entry point replaces the
Python process with it, so signals (Ctrl-C finishing a recording) reach it
directly, and names this Python as the one `--report` runs: the one this
package, and numpy and matplotlib when installed with ``[report]``, are
importable from.
"""
import os
import sys


def executable() -> str:
    """The path of the bundled `cdm` program."""
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), "bin", "cdm")


def main() -> None:
    """Runs the bundled `cdm` with this process's arguments (never returns)."""
    exe = executable()
    if not os.access(exe, os.X_OK):
        sys.stderr.write("cdm: this cdm package has no cdm command (%s): install the cdm-haptics wheel, or build "
                         "the command from source (README.md)\n" % exe)
        sys.exit(1)
    env = dict(os.environ)
    env.setdefault("PYTHON", sys.executable)
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(exe, ["cdm"] + sys.argv[1:], env)
