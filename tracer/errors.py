"""The one exception type for bad input: the CLI prints it as one line and exits with 2."""

from __future__ import annotations


class InputError(Exception):
    """Bad user input (scene file, mesh, option, EXR). ``str()`` is the whole message.

    ``where`` names the file and ``key`` the place inside it (``camera.fov``,
    ``shapes[2].file``); both appear in the message so the user can go straight to the fault.
    """

    def __init__(self, message: str, where: str | None = None, key: str | None = None):
        self.where = where
        self.key = key
        prefix = ""
        if where:
            prefix += f"{where}: "
        if key:
            prefix += f"{key}: "
        super().__init__(one_line(prefix + message))


def one_line(text: str) -> str:
    """``text`` with every character that is not printable (a newline or a terminal escape in a
    key, a file name or a material name the user wrote) shown as its escape, so that an error
    is always one line and cannot drive the terminal."""
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
