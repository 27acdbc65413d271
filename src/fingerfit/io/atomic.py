"""All-or-nothing writes: a file, a set of files or a folder appears complete or not at all.

Every output of fingerfit goes through here, so the same rules hold for every command:

* a target that is a folder, or a file whose mode bits say read-only, is refused
  (checked on the mode bits: as root ``os.access`` always says writable);
* :func:`write_files` replaces an existing target only when asked to (``overwrite``);
* a set of files (:func:`write_files`) or a folder (:func:`staged_directory`) is built
  beside its target and moved into place only when all of it is complete; a failure
  part-way leaves the previous state;
* errors raised while a folder is staged name the user's path, never the staging one;
* :func:`refuse_writing_inputs` stops a command from writing onto one of its inputs.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import IO

from ..errors import FingerfitError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_target(path: str | Path, *, overwrite: bool = True) -> None:
    """Refuse an output path that cannot or must not be replaced.

    Parameters
    ----------
    path : str or Path
        File about to be written.
    overwrite : bool
        Whether an existing file may be replaced.

    Raises
    ------
    FingerfitError
        The target is a folder, exists (without ``overwrite``), is read-only by its
        mode bits, or a parent of it is a file.
    """
    path = Path(path)
    if path.is_dir():
        raise FingerfitError("is a folder, not a file", path=path)
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise FingerfitError(f"cannot write: '{parent}' is a file, not a folder", path=path)
            break
    if path.exists():
        if not overwrite:
            raise FingerfitError("exists; pass --overwrite to replace it", path=path)
        if not path.stat().st_mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH):
            raise FingerfitError("is read-only; not replaced", path=path)


def make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and every missing folder above it.

    Returns
    -------
    list of Path
        The folders this call created, deepest first (:func:`remove_made`).

    Raises
    ------
    OSError
        A folder could not be created (those created before it are removed).
    """
    made = []
    at = Path(folder)
    while not at.exists() and at.parent != at:
        made.append(at)
        at = at.parent
    try:
        for f in reversed(made):
            f.mkdir(exist_ok=True)
    except OSError:
        remove_made(made)
        raise
    return made


def remove_made(folders: Iterable[Path]) -> None:
    """Remove the folders :func:`make_parents` created, deepest first, each only while it is
    empty: a refused or failed command leaves no folder behind it."""
    for f in folders:
        try:
            f.rmdir()
        except OSError:  # not empty (something else wrote there), or gone
            return


def _temp_beside(path: Path, suffix: str = ".part") -> tuple[int, Path, list[Path]]:
    """Create the parent folders and an empty temporary file beside ``path``; the folders
    created (:func:`make_parents`) come back too, for removal on failure."""
    made: list[Path] = []
    try:
        made = make_parents(path.parent)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
        os.chmod(tmp, 0o666 & ~_umask())
    except OSError as exc:
        remove_made(made)
        raise FingerfitError(f"cannot write ({exc.strerror or exc})", path=path) from None
    return fd, Path(tmp), made


@contextlib.contextmanager
def atomic_path(path: str | Path, *, suffix: str = ".part") -> Iterator[Path]:
    """A temporary path beside ``path``, renamed over ``path`` when the block succeeds.

    For writers that take a file name (ezc3d): the block writes the yielded path. If
    the block raises, the temporary file is removed and ``path`` is left untouched, as is
    its folder (one it had to create is removed again). ``path`` is checked first with
    :func:`check_target` (an existing file is replaced).

    Parameters
    ----------
    path : str or Path
        The file to write.
    suffix : str
        End of the temporary name (a writer that appends its own extension to other
        names needs it here, e.g. ``".part.c3d"``).

    Yields
    ------
    Path
        The temporary file (created empty, with the usual permissions).
    """
    path = Path(path)
    check_target(path)
    fd, tmp, made = _temp_beside(path, suffix)
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        remove_made(made)
        raise FingerfitError(f"cannot write ({exc.strerror or exc})", path=path) from None
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        remove_made(made)
        raise


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "w", **kwargs) -> Iterator[IO]:
    """Open a temporary file beside ``path``; rename it over ``path`` on success.

    If the block raises, the temporary file is removed and ``path`` is left
    untouched, so no half-written output ever exists (:func:`atomic_path`).

    Parameters
    ----------
    path : str or Path
        The file to write.
    mode : str
        ``"w"`` (text) or ``"wb"`` (bytes); ``kwargs`` go to :func:`open`.
    """
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh


def write_files(files: Mapping[Path, str | bytes], *, overwrite: bool = True) -> list[Path]:
    """Write several files all-or-nothing.

    Every target is checked (:func:`check_target`) and every temporary file written
    before any is moved into place; if moving one fails, those already moved are
    restored to what they were, so a failure leaves no new output and no lost file.

    Parameters
    ----------
    files : mapping of Path to str or bytes
        Target -> complete content (text is written UTF-8 with ``\\n`` line ends).
    overwrite : bool
        Whether existing targets may be replaced.

    Returns
    -------
    list of Path
        The targets, in the order given.

    Raises
    ------
    FingerfitError
        Naming the target that could not be written.
    """
    paths = [Path(p) for p in files]
    if len({p.resolve() for p in paths}) != len(paths):
        raise FingerfitError("the same file is named twice as an output", path=paths[0])
    for p in paths:
        check_target(p, overwrite=overwrite)
    temps: dict[Path, Path] = {}
    backups: dict[Path, Path] = {}
    placed: list[Path] = []
    made: list[Path] = []  # folders created, removed again on failure
    current = paths[0] if paths else Path()
    try:
        for current, content in zip(paths, files.values(), strict=True):
            fd, temps[current], new = _temp_beside(current)
            made = new + made
            data = content.encode("utf-8") if isinstance(content, str) else content
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
        for current in paths:
            if current.exists():
                backups[current] = current.with_name(f".{current.name}.{os.getpid()}.previous")
                os.link(current, backups[current])
            os.replace(temps.pop(current), current)
            placed.append(current)
    except OSError as exc:
        for p in placed:
            with contextlib.suppress(OSError):
                if p in backups:
                    os.replace(backups.pop(p), p)
                else:
                    os.unlink(p)
        raise FingerfitError(f"cannot write ({exc.strerror or exc})", path=current) from None
    finally:
        for tmp in [*temps.values(), *backups.values()]:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        if len(placed) < len(paths):
            remove_made(made)
    return paths


def _renamed(exc: FingerfitError, staging: Path, target: Path) -> FingerfitError:
    """The same error naming ``target`` wherever it named ``staging``."""
    path = exc.path
    if path is not None and path.is_relative_to(staging):
        path = target / path.relative_to(staging)
    reason = exc.reason.replace(str(staging), str(target))
    exc.__init__(reason, path=path, line=exc.line, field=exc.field)  # type: ignore[misc]
    return exc


def check_folder_target(target: str | Path, *, overwrite: bool = False, hint: str = "") -> None:
    """Refuse a folder :func:`staged_directory` would not write: a file of that name, or a
    non-empty folder without ``overwrite``.

    Parameters
    ----------
    target : str or Path
    overwrite : bool
    hint : str
        Added to the refusal of a non-empty folder (what else ``--overwrite`` replaces).

    Raises
    ------
    FingerfitError
        Naming ``target``.
    """
    target = Path(target)
    if target.exists() and not target.is_dir():
        raise FingerfitError("exists and is not a folder", path=target)
    if target.is_dir() and any(target.iterdir()) and not overwrite:
        raise FingerfitError(
            f"exists and is not empty; pass --overwrite to replace it{hint}", path=target
        )


@contextlib.contextmanager
def staged_directory(target: str | Path, *, overwrite: bool = False) -> Iterator[Path]:
    """Build a folder in a hidden sibling; move it to ``target`` when the block succeeds.

    Parameters
    ----------
    target : str or Path
        The folder to create. An empty existing folder is fine; a non-empty one is
        replaced only with ``overwrite`` (and only after the new one is complete).

    Yields
    ------
    Path
        The staging folder to write into.

    Raises
    ------
    FingerfitError
        ``target`` is a file, or a non-empty folder without ``overwrite``; errors
        raised in the block name ``target`` instead of the staging folder. On any
        failure the folders above ``target`` that it created are removed again.
    """
    target = Path(target)
    check_folder_target(target, overwrite=overwrite)
    made: list[Path] = []
    try:
        made = make_parents(target.parent)
        staging = Path(
            tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".partial", dir=target.parent)
        )
        os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes it 0700; the result is a normal folder
    except OSError as exc:
        remove_made(made)
        raise FingerfitError(f"cannot create ({exc.strerror or exc})", path=target) from None
    done = False
    try:
        try:
            yield staging
        except FingerfitError as exc:
            raise _renamed(exc, staging, target) from None
        old = None
        if target.exists():
            old = target.with_name(f".{target.name}.{os.getpid()}.previous")
            os.replace(target, old)
        try:
            os.replace(staging, target)
        except OSError as exc:
            if old is not None:
                os.replace(old, target)
            raise FingerfitError(f"cannot create ({exc.strerror or exc})", path=target) from None
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
        done = True
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        if not done:
            remove_made(made)


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
