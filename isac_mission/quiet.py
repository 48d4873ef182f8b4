"""Silence HiGHS's copyright banner, which it prints on stdout at its first use in a process."""

from __future__ import annotations

import os


def quiet_highs_banner() -> None:
    """Construct HiGHS once with file descriptor 1 sent to /dev/null (idempotent in effect)."""
    import highspy

    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            highspy.Highs()
    finally:
        os.dup2(saved, 1)
        os.close(saved)
