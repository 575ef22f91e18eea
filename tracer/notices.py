"""Notes for the user that are not errors: one line each, such as what a Mitsuba scene asks for
and tracer does not do (its integrator, pixel filter, ...).

The library hands each note to the handler installed here; without one (the default for API
users) notes are dropped. The command line installs a handler that prints each distinct note
once on stderr. Kept free of heavy imports, so that the command line can install its handler
before it loads numba.
"""

from __future__ import annotations

from collections.abc import Callable

_handler: Callable[[str], None] | None = None


def set_handler(handler: Callable[[str], None] | None) -> Callable[[str], None] | None:
    """Make ``handler`` receive every later note (None: drop them); returns the previous one."""
    global _handler
    previous, _handler = _handler, handler
    return previous


def note(line: str) -> None:
    """Pass one line to the installed handler, if any."""
    if _handler is not None:
        _handler(line)
