"""A small input file read whole: its bytes, its UTF-8 text or its TOML, every failure a
one-line :class:`~fingerfit.errors.FingerfitError` naming the file (and the line)."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from ..errors import FingerfitError


def read_bytes(path: Path) -> bytes:
    """The file's bytes.

    Raises
    ------
    FingerfitError
        ``file not found``, or ``cannot read: <reason>``.
    """
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise FingerfitError("file not found", path=path) from None
    except OSError as exc:
        raise FingerfitError(f"cannot read: {exc.strerror}", path=path) from None


def read_text(path: Path) -> str:
    """The file's text (UTF-8; a leading byte-order mark dropped).

    Raises
    ------
    FingerfitError
        Those of :func:`read_bytes`, or ``not UTF-8 text (byte N)`` naming the line.
    """
    raw = read_bytes(path)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise FingerfitError(f"not UTF-8 text (byte {exc.start})", path=path, line=line) from None


def read_toml(path: Path) -> dict:
    """The file's TOML document.

    Raises
    ------
    FingerfitError
        Those of :func:`read_text`, or ``invalid TOML (<reason>)`` naming the line.
    """
    text = read_text(path)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        found = re.search(r"at line (\d+)", str(exc))
        raise FingerfitError(
            f"invalid TOML ({str(exc).split(' (at')[0]})",
            path=path,
            line=int(found.group(1)) if found else None,
        ) from None
