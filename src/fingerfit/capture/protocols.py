"""The protocols ``fingerfit capture`` records: which digits' joints each shows and the
recordings it takes, in the order it proposes them (``docs/capture.md``).

A new protocol (a landmark or pinch recording, say) is an entry here and, when it needs
more than a recording and its evidence, a module of its own beside this one.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import FingerfitError

#: Protocol -> (the digits whose joints it shows (None: every digit of the session), the
#: recordings it takes in order). Each is listed under ``grasp`` in ``session.toml``:
#: the fit pools every calibration recording (``docs/formats.md``).
PROTOCOLS: dict[str, tuple[tuple[str, ...] | None, tuple[str, ...]]] = {
    "grasp": (None, ("grasp.csv",)),
    "thumb": (("thumb",), ("thumb_circumduction.csv", "thumb_opposition.csv")),
    # The thumb's pad on each finger's in turn; the holds are marked in events.csv
    # (:mod:`.pinch`).
    "pinch": (("thumb",), ("pinch.csv",)),
}
#: The protocols whose recordings have pad-to-pad holds, marked in ``events.csv``
#: (:mod:`.pinch`): opposition touches the thumb's pad to each finger's, pinches too.
HOLD_PROTOCOLS = ("thumb", "pinch")
#: The ``session.toml`` list every protocol's recording joins.
RECORDING_LIST = "grasp"


def shown_digits(protocol: str, digits: list[str]) -> list[str]:
    """The digits of the session whose joints ``protocol`` shows.

    Raises
    ------
    FingerfitError
        ``field '--protocol'``: the protocol is for digits the session does not have.
    """
    wanted = PROTOCOLS[protocol][0]
    shown = [d for d in digits if wanted is None or d in wanted]
    if not shown:
        raise FingerfitError(
            f"protocol '{protocol}' is for the {', '.join(wanted or ())}, which the session "
            "does not have",
            field="--protocol",
        )
    return shown


def next_recording(protocol: str, folder: Path) -> str:
    """The protocol's first recording the folder does not hold (listed in its
    ``session.toml`` or not: a listed recording whose file is missing is recorded again).

    Raises
    ------
    FingerfitError
        ``field '--name'``: the folder holds every recording of the protocol.
    """
    names = PROTOCOLS[protocol][1]
    for name in names:
        if not (folder / name).exists():
            return name
    raise FingerfitError(
        f"the folder has {' and '.join(names)}: give --name for another recording",
        field="--name",
    )
