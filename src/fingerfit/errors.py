"""The one user-facing error type.

Every problem with a user's input (a file, a field, a flag) is raised as
:class:`FingerfitError`, whose message is a single line naming the file and the
line or field at fault. The command-line interface prints that line and exits
with status 2; it never shows a traceback for these.
"""

from __future__ import annotations

from pathlib import Path


def shown(value: object, n: int = 40) -> str:
    """A value as shown in a one-line message: control characters and non-ASCII escaped
    (``\\n``, ``\\xe9``), at most ``n`` characters (longer ones end in ``...``)."""
    s = str(value).encode("unicode_escape").decode("ascii")
    return s if len(s) <= n else s[: n - 3] + "..."


class FingerfitError(ValueError):
    """A problem with user input, reported as one line.

    Parameters
    ----------
    message : str
        What is wrong, in plain words.
    path : str or Path, optional
        The file at fault.
    line : int, optional
        1-based line number in ``path``.
    field : str, optional
        The field, column or key at fault.
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        line: int | None = None,
        field: str | None = None,
    ) -> None:
        self.path = None if path is None else Path(path)
        self.line = line
        self.field = field
        self.reason = message
        where = ""
        if path is not None:
            where = str(path)
            if line is not None:
                where += f":{line}"
            where += ": "
        if field is not None:
            where += f"field '{field}': "
        super().__init__(f"{where}{message}")
