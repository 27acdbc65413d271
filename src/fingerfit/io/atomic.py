"""All-or-nothing writes: a file appears complete or not at all."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO

from ..errors import FingerfitError


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "w", **kwargs) -> Iterator[IO]:
    """Open a temporary file beside ``path``; rename it over ``path`` on success.

    If the block raises, the temporary file is removed and ``path`` is left
    untouched, so no half-written output ever exists.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    try:
        with os.fdopen(fd, mode, **kwargs) as fh:
            yield fh
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def _same_file(a: Path, b: Path) -> bool:
    """Whether two paths name one file (symlinks and hard links included)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def refuse_writing_inputs(outputs: Iterable[str | Path], inputs: Iterable[str | Path]) -> None:
    """Refuse an output path that names one of the command's inputs.

    Parameters
    ----------
    outputs, inputs : iterable of str or Path
        Files the command is about to write, and files (or directories) it reads.
        An output inside an input directory is allowed; an output that *is* an
        input file, through any link, is not.

    Raises
    ------
    FingerfitError
        Naming the output and the input it would overwrite.
    """
    ins = [Path(p) for p in inputs]
    for o in (Path(p) for p in outputs):
        for i in ins:
            if _same_file(o, i):
                raise FingerfitError(f"would overwrite the input '{i}'", path=o)
