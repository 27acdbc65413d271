"""Text files of the robot export, written all-or-nothing."""

from __future__ import annotations

from pathlib import Path

from ..io.atomic import write_files


def write_text(files: dict[Path, str], *, overwrite: bool = True) -> list[Path]:
    """Write several text files all-or-nothing (:func:`fingerfit.io.atomic.write_files`).

    Parameters
    ----------
    files : dict[Path, str]
        Path -> complete text (written UTF-8 with ``\n`` line ends).
    overwrite : bool
        Whether existing files may be replaced (``--overwrite``).

    Returns
    -------
    list of Path

    Raises
    ------
    FingerfitError
        Naming the path that could not or must not be written.
    """
    return write_files(files, overwrite=overwrite)
