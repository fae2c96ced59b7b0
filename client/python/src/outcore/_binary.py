"""Where the `outcore` executable is, for the helpers that run it
(outcore.pack): the one lookup, so every helper finds the same binary.

Thread-safety: pure function (reads the environment).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

ENVIRONMENT_VARIABLE = "OUTCORE_BINARY"


def find_outcore_binary(binary=None) -> Path:
    """The `outcore` executable: `binary` when given (a path), else
    $OUTCORE_BINARY, else `outcore` on the PATH. Raises FileNotFoundError
    saying what was tried when there is none (the Python package does not
    ship the C++ binary: build it, scripts/build.sh, and point one of these
    at build/client/outcore)."""
    if binary is not None:
        candidate, origin = Path(binary), "the binary argument"
    elif os.environ.get(ENVIRONMENT_VARIABLE):
        candidate, origin = Path(os.environ[ENVIRONMENT_VARIABLE]), f"${ENVIRONMENT_VARIABLE}"
    else:
        found = shutil.which("outcore")
        if found is None:
            raise FileNotFoundError(
                "cannot find the outcore binary: pass binary=..., set $OUTCORE_BINARY, "
                "or put outcore on the PATH (it is built as build/client/outcore)"
            )
        return Path(found)
    if not candidate.is_file() or not os.access(candidate, os.X_OK):
        raise FileNotFoundError(f"{origin} names {str(candidate)!r}, which is not an executable file")
    return candidate
