"""What a run tells its user, through the standard :mod:`logging` module (logger ``"fdem"``).

A case reports its progress (meshing, time step, cost estimate, files written) with
:func:`say`, its doubts with :func:`warn`, and its result with ``print``. :func:`configure`
sends the ``fdem`` logger to standard output as plain lines (warnings prefixed ``warning:``), at
INFO, or at WARNING with ``--quiet`` (then only warnings and the result are printed). A program
that embeds ``fdem`` and gives the ``fdem`` logger a handler of its own keeps it:
:func:`configure` then only sets the level.
"""
from __future__ import annotations

import logging
import sys

__all__ = ["LOGGER", "configure", "say", "warn"]

LOGGER = logging.getLogger("fdem")


class _StdoutHandler(logging.Handler):
    """Plain lines on the *current* ``sys.stdout`` (a test's capture, a redirected stream)."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage()
            if record.levelno >= logging.WARNING:
                text = f"{record.levelname.lower()}: {text}"
            sys.stdout.write(text + "\n")
            sys.stdout.flush()
        except Exception:  # noqa: BLE001 - logging must never end a run
            self.handleError(record)


_HANDLER = _StdoutHandler()


def configure(quiet: bool = False) -> None:
    """Messages at INFO (``quiet``: WARNING) on standard output, unless the embedding program
    gave the ``fdem`` logger a handler of its own."""
    LOGGER.setLevel(logging.WARNING if quiet else logging.INFO)
    own = [h for h in LOGGER.handlers if h is not _HANDLER]
    if not own and _HANDLER not in LOGGER.handlers:
        LOGGER.addHandler(_HANDLER)
        LOGGER.propagate = False


def say(message: str) -> None:
    """Progress a user may want to read (shown unless ``--quiet``)."""
    if not LOGGER.handlers:
        configure()
    LOGGER.info(message)


def warn(message: str) -> None:
    """Something the user should know even with ``--quiet`` (printed ``warning: ...``)."""
    if not LOGGER.handlers:
        configure()
    LOGGER.warning(message)
