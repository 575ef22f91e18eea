"""The one exception type for bad input: the CLI prints it as one line and exits with 2."""

from __future__ import annotations

# Echoed user values (a name, a key, an attribute) are cut to this many characters, with their
# length said, so that a hostile 60 MB material name gives a short error line.
SHOWN_CHARACTERS = 80
# A whole message is cut to this many characters (its middle dropped, the count said): the net
# under every place that echoes a value without ``shown``.
MAX_MESSAGE = 2000


class InputError(Exception):
    """Bad user input (scene file, mesh, option, EXR). ``str()`` is the whole message.

    ``where`` names the file and ``key`` the place inside it (``camera.fov``,
    ``shapes[2].file``); both appear in the message so the user can go straight to the fault.
    The message is one printable line of at most ``MAX_MESSAGE`` characters.
    """

    def __init__(self, message: str, where: str | None = None, key: str | None = None):
        self.where = where
        self.key = key
        prefix = ""
        if where:
            prefix += f"{shown(where, 4 * SHOWN_CHARACTERS)}: "
        if key:
            prefix += f"{shown(key)}: "
        super().__init__(one_line(prefix + message))


def shown(value: object, limit: int = SHOWN_CHARACTERS) -> str:
    """``value`` as text for an error line: itself if short, else its first ``limit``
    characters, an ellipsis and its length (``'abc…' (60000000 characters)`` without quotes)."""
    text = value if isinstance(value, str) else str(value)
    if len(text) <= limit:
        return text
    return f"{text[:limit]}… ({len(text)} characters)"


def one_line(text: str) -> str:
    """``text`` with every character that is not printable (a newline or a terminal escape in a
    key, a file name or a material name the user wrote) shown as its escape, so that an error
    is always one line and cannot drive the terminal; at most ``MAX_MESSAGE`` characters (the
    middle cut out and counted)."""
    if len(text) > MAX_MESSAGE:
        # Cut before escaping: escaping a 60 MB string character by character takes a minute.
        half = MAX_MESSAGE // 2
        text = f"{text[:half]} … ({len(text) - 2 * half} characters cut) … {text[-half:]}"
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)
