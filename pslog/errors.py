"""The one exception base of pslog.

Every failure a user can cause (bad file, bad value, bad rig) raises a subclass of
:class:`PslogError` with a one-line message naming the offending value; the CLI turns it
into ``error: <message>`` on stderr and exit code 1.
"""


class PslogError(Exception):
    """Base of every error pslog raises on purpose."""


class RigError(PslogError):
    """A rig or camera description is malformed or inconsistent."""


class LogFormatError(PslogError):
    """A file is missing, not an MCAP, not a pslog session, or damaged."""


class InputError(PslogError):
    """A user-supplied table (CSV, points) or argument value is malformed."""


class FusionError(PslogError):
    """A fusion method cannot run on the given rig or detections."""


class OutputExistsError(PslogError):
    """An output file exists and ``--force`` was not given."""


def shown(value: object, limit: int = 60) -> str:
    """``repr(value)`` for a one-line message: its whitespace runs (a numpy array's repr spans
    lines) made single spaces, cut to ``limit`` characters."""
    return " ".join(repr(value).split())[:limit]


_PLAIN = frozenset("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789@%+=:,./-_")


def shell_word(path: object) -> str:
    """``path`` as one word of a command a message suggests (``run 'pslog recover P -o
    FIXED.mcap'``), for a user to paste into a POSIX shell: unchanged if it holds only
    characters no shell reads specially (non-ASCII letters too), else in double quotes
    with ``"``, ``$``, backquote and backslash escaped (``"my match.mcap"``: a path with a
    space, pasted unquoted, is two arguments), and each ``!`` outside them, escaped
    (``"my"\\!"x.mcap"``): an interactive bash (or zsh) expands ``!`` inside double quotes
    from its history ("event not found"), and a backslash there would stay in the path
    (review, session 36).
    """
    text = str(path)
    if text and all(c in _PLAIN or (ord(c) > 127 and c.isprintable()) for c in text):
        return text
    escaped = "".join("\\" + c if c in '"$`\\' else '"\\!"' if c == "!" else c
                      for c in text)
    return f'"{escaped}"'
