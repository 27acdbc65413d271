"""An LSL stream of sensor poses as a live source (``lsl:NAME``)."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator

import numpy as np

from ...errors import FingerfitError, shown
from ...session import UNITS_TO_MM, PoseSeries, Recording
from ...transforms import matrix_from_quat_wxyz
from .. import require
from .common import (
    DEFAULT_RECONNECT_S,
    MAX_BLOCK,
    NO_DATA_SECONDS,
    POLL_S,
    Block,
    SourceStats,
    _recording,
    _retry,
    _stderr_warning,
    check_reconnect,
)

_QUAT = ("qw", "qx", "qy", "qz")
_UNIT_MM = {
    "mm": 1.0,
    "millimeters": 1.0,
    "millimetres": 1.0,
    "cm": 10.0,
    "centimeters": 10.0,
    "centimetres": 10.0,
    "m": 1000.0,
    "meters": 1000.0,
    "metres": 1000.0,
    "in": UNITS_TO_MM["in"],
    "inches": UNITS_TO_MM["in"],
}


def mocap_layout(
    labels: list[str], units: list[str], sensors: list[str], name: str
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], np.ndarray]:
    """Channel indices of each sensor's position and quaternion in an LSL MoCap stream.

    Parameters
    ----------
    labels, units : list of str
        Channel labels (``<sensor>.x|y|z``, ``<sensor>.qw|qx|qy|qz``) and units.
    sensors : list of str
        Sensors the model uses; a sensor with none of its channels is absent (the
        stream's layout is checked by the caller), one with some of them is an error.
    name : str
        Stream name, for messages.

    Returns
    -------
    positions, quaternions : dict[str, ndarray]
        sensor -> channel indices ``(3,)`` x, y, z and ``(4,)`` w, x, y, z, for the
        sensors the stream has.
    scale : ndarray, shape (n_channels,)
        Factor to millimetres per channel (1 for quaternion channels).

    Raises
    ------
    FingerfitError
        A sensor with some but not all of its seven channels, no sensor at all, or a
        position unit not understood.
    """
    if not any(labels):
        raise FingerfitError(
            f"{len(labels)} channel(s) without labels: need <sensor>.x|y|z and "
            "<sensor>.qw|qx|qy|qz for each sensor",
            path=f"lsl:{name}",
        )
    where = {lab: i for i, lab in enumerate(labels)}
    scale = np.ones(len(labels))
    pos, quat = {}, {}
    for s in sensors:
        pi = [where.get(f"{s}.{c}") for c in "xyz"]
        qi = [where.get(f"{s}.{c}") for c in _QUAT]
        if all(i is None for i in pi + qi):
            continue  # not in this stream
        if None in pi or None in qi:
            raise FingerfitError(
                f"no channels {s}.x|y|z and {s}.qw|qx|qy|qz (labels: "
                f"{shown(', '.join(labels), 80)})",
                path=f"lsl:{name}",
            )
        for i in pi:
            scale[i] = _length_scale(labels[i], units[i], name)
        pos[s], quat[s] = np.array(pi), np.array(qi)
    if not pos:
        raise FingerfitError(
            f"no channels {sensors[0]}.x|y|z and {sensors[0]}.qw|qx|qy|qz, nor of any other "
            f"sensor of the model (labels: {shown(', '.join(labels), 80)})",
            path=f"lsl:{name}",
        )
    return pos, quat, scale


def _length_scale(label: str, unit: str, name: str) -> float:
    """A position channel's factor to millimetres; a clear error for a unit not
    understood."""
    u = unit.strip().lower()
    if u not in _UNIT_MM:
        raise FingerfitError(
            f"channel {label}: unit '{shown(unit)}' is not a length unit ({', '.join(_UNIT_MM)})",
            path=f"lsl:{name}",
        )
    return _UNIT_MM[u]


def marker_layout(
    labels: list[str], units: list[str], markers: list[str], name: str
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Channel indices of each marker's position in an LSL MoCap stream of markers.

    A marker's channels are labelled ``<marker>_X|_Y|_Z`` (the Qualisys LSL app's labels)
    or ``<marker>.x|y|z`` (a pose stream's, :func:`mocap_layout`); their unit is in the
    channel metadata (``meters``, ``mm``, ...).

    Parameters
    ----------
    labels, units : list of str
        Channel labels and units.
    markers : list of str
        The model's markers; one with none of its channels is absent (the caller checks
        the layout), one with some of them is an error.
    name : str
        Stream name, for messages.

    Returns
    -------
    positions : dict[str, ndarray]
        marker -> channel indices ``(3,)`` x, y, z, for the markers the stream has.
    scale : ndarray, shape (n_channels,)
        Factor to millimetres per channel.
    """
    where = {lab: i for i, lab in enumerate(labels)}
    scale = np.ones(len(labels))
    pos = {}
    for m in markers:
        found = None
        for names in ([f"{m}_{c}" for c in "XYZ"], [f"{m}.{c}" for c in "xyz"]):
            idx = [where.get(k) for k in names]
            if all(i is None for i in idx):
                continue
            if None in idx:
                raise FingerfitError(
                    f"marker {m}: not all of {'|'.join(names)} (labels: "
                    f"{shown(', '.join(labels), 80)})",
                    path=f"lsl:{name}",
                )
            found = idx
            break
        if found is None:
            continue
        for i in found:
            scale[i] = _length_scale(labels[i], units[i], name)
        pos[m] = np.array(found)
    if not pos:
        raise FingerfitError(
            f"no channels {markers[0]}_X|_Y|_Z (or {markers[0]}.x|y|z), nor of any other "
            f"marker of the model (labels: {shown(', '.join(labels), 80)})",
            path=f"lsl:{name}",
        )
    return pos, scale


#: Seconds a reconnecting LSL source waits for a stream it found to answer.
LSL_CONNECT_S = 0.5
#: LSL channel formats a pose stream may have (positions and unit quaternions).
LSL_FORMATS = ("float32", "double64")


class LslSource:
    """An LSL stream of sensor poses (type ``MoCap``).

    The stream is checked when it is found (type ``MoCap``, channel format float32 or
    double64, the seven channels of every sensor): a stream that fails ends the stream
    before anything is written, with one line. When the stream disappears (its outlet is
    destroyed: liblsl's ``LostError``) the source warns once (:attr:`warn`) and looks for
    a stream of that name again, 0.05, 0.1, 0.2 ... s apart (at most 1 s), for up to
    ``reconnect`` s, yielding None meanwhile (the stream's watchdog marks the silence);
    the one it finds is checked as the first was.

    Parameters
    ----------
    name : str
        Stream name to resolve.
    sensors : list of str
        Sensors the model needs; each must have ``<sensor>.x|y|z`` and
        ``<sensor>.qw|qx|qy|qz`` channels.
    timeout : float
        Seconds to wait for the stream to appear.
    reconnect : float
        Seconds to keep looking for a lost stream (0: the stream ends at once).
    markers : bool
        The stream carries marker positions (``sensors`` are then the model's markers,
        :func:`marker_layout`; the blocks' recordings hold
        :attr:`~fingerfit.session.Recording.markers`), not poses.
    check : callable, optional
        Called with the set of sensors a stream it finds has (each time it finds one);
        raises :class:`FingerfitError` when they cannot determine the model's joints
        (``fingerfit stream`` checks the layout, :func:`fingerfit.track.check_layout`).
        Default: every sensor of ``sensors`` is needed.

    Attributes
    ----------
    warn : callable
        Called with the one-line warning of an outage (default: printed on stderr).
    """

    live = True

    def __init__(
        self,
        name: str,
        sensors: list[str],
        timeout: float = 5.0,
        reconnect: float = DEFAULT_RECONNECT_S,
        check: Callable[[set[str]], None] | None = None,
        markers: bool = False,
    ) -> None:
        self._pylsl = pylsl = require("pylsl")
        self.markers = markers
        self.check = check or self._every_sensor
        self.name = f"lsl:{name}"
        self.stream = name
        self.sensors = sensors
        self.timeout = timeout
        self.reconnect = check_reconnect(reconnect)
        self.stats = SourceStats()
        self.warn: Callable[[str], None] = _stderr_warning
        found = pylsl.resolve_byprop("name", name, minimum=1, timeout=timeout)
        if not found:
            raise FingerfitError(
                f"no LSL stream named '{shown(name)}' within {timeout:g} s", path=self.name
            )
        try:
            self._connect(found[0], timeout)
        except FingerfitError:
            raise
        except Exception as exc:  # pylsl's TimeoutError, LostError
            raise FingerfitError(
                f"the stream was found but did not answer ({exc})", path=self.name
            ) from None
        self._clock = pylsl.local_clock
        self._offset = pylsl.local_clock() - time.monotonic()

    def _connect(self, info, timeout: float) -> None:
        """Open an inlet on ``info`` and check its type, format and channels.

        Parameters
        ----------
        info : pylsl.StreamInfo
            As resolved.
        timeout : float
            Seconds to wait for the stream's full description and for it to open.

        Raises
        ------
        FingerfitError
            Not ``MoCap``, a channel format other than float32 / double64, or a sensor
            without its seven channels (the inlet is closed again).
        Exception
            pylsl's ``TimeoutError`` / ``LostError``: the stream did not answer (the
            inlet is closed again).
        """
        pylsl = self._pylsl
        # (the Qualisys LSL app's marker streams are of type "Mocap")
        if info.type() != "MoCap" and not (self.markers and info.type().lower() == "mocap"):
            raise FingerfitError(
                f"stream type is '{shown(info.type())}', not MoCap", path=self.name
            )
        fmt = _format_name(info.channel_format())
        if fmt not in LSL_FORMATS:
            raise FingerfitError(
                f"channel format is {fmt}, not {' or '.join(LSL_FORMATS)} (positions and "
                "unit quaternions)",
                path=self.name,
            )
        # recover=False: a destroyed outlet raises LostError at once instead of liblsl
        # waiting for it silently; the source then looks for the stream itself.
        inlet = pylsl.StreamInlet(info, max_buflen=10, processing_flags=0, recover=False)
        try:
            full = inlet.info(timeout=timeout)
            ch = full.desc().child("channels").child("channel")
            labels, units = [], []
            for _ in range(full.channel_count()):
                labels.append(ch.child_value("label"))
                units.append(ch.child_value("unit"))
                ch = ch.next_sibling()
            if self.markers:
                pos, scale = marker_layout(labels, units, self.sensors, self.stream)
                quat: dict[str, np.ndarray] = {}
            else:
                pos, quat, scale = mocap_layout(labels, units, self.sensors, self.stream)
            self.check(set(pos))
            inlet.open_stream(timeout=timeout)
        except BaseException:
            with contextlib.suppress(Exception):
                inlet.close_stream()
            raise
        self.inlet, self.pos, self.quat, self.scale = inlet, pos, quat, scale

    def _every_sensor(self, present: set[str]) -> None:
        """The default layout check: every sensor of :attr:`sensors`."""
        for s in self.sensors:
            if s not in present:
                raise FingerfitError(f"no channels {s}.x|y|z and {s}.qw|qx|qy|qz", path=self.name)

    def _refind(self) -> Iterator[None]:
        """The stream was lost: warn once and find it again within ``reconnect`` s
        (yielding None while waiting).

        Raises
        ------
        FingerfitError
            Not back in time (or ``reconnect`` is 0); the stream that came back does not
            check (:meth:`_connect`).
        """
        with contextlib.suppress(Exception):
            self.inlet.close_stream()
        if self.reconnect <= 0:
            raise FingerfitError("stream lost (its outlet was closed)", path=self.name)
        self.stats.outages += 1
        self.warn(
            f"{self.name}: stream lost (its outlet was closed); looking for it again "
            f"(up to {self.reconnect:g} s)"
        )

        def attempt() -> bool:
            found = self._pylsl.resolve_byprop("name", self.stream, minimum=1, timeout=POLL_S)
            if not found:
                return False
            try:  # a stream that fails the checks ends the stream (FingerfitError)
                self._connect(found[0], LSL_CONNECT_S)
            except FingerfitError:
                raise
            except Exception:  # found, but gone again (the old outlet, closing): retry
                return False
            return True

        back = yield from _retry(attempt, time.monotonic() + self.reconnect)
        if not back:
            raise FingerfitError(
                f"stream lost (its outlet was closed); not back within {self.reconnect:g} s",
                path=self.name,
            )
        self.stats.reconnects += 1

    def blocks(self) -> Iterator[Block | None]:
        """Samples as they are pulled (None after a poll without data); time = the
        sender's LSL timestamp, arrival = the moment the pull returned.

        Raises
        ------
        FingerfitError
            No sample for :data:`NO_DATA_SECONDS` (the sender stopped sending), or the
            stream lost and not back within ``reconnect`` s.
        """
        quiet_since = time.monotonic()
        t_first = None
        lost = _lsl_lost_error(self._pylsl)
        while True:
            try:
                data, stamps = self.inlet.pull_chunk(timeout=POLL_S, max_samples=MAX_BLOCK)
            except lost:
                yield from self._refind()
                quiet_since = time.monotonic()
                continue
            now = time.monotonic()
            if not stamps:
                if now - quiet_since > NO_DATA_SECONDS:
                    raise FingerfitError(f"no samples for {NO_DATA_SECONDS:g} s", path=self.name)
                yield None  # nothing this poll: the loop can check its duration
                continue
            quiet_since = now
            x = np.asarray(data, dtype=float) * self.scale
            ts = np.asarray(stamps, dtype=float)
            if t_first is None:
                t_first = ts[0]
            n = x.shape[0]
            if self.markers:
                markers = {m: x[:, pi] for m, pi in self.pos.items()}
                yield Block(
                    Recording(self.name, ts - t_first, {}, markers=markers), np.full(n, now)
                )
                continue
            poses = {}
            for s, pi in self.pos.items():
                q = x[:, self.quat[s]]
                rot = np.full((n, 3, 3), np.nan)
                norm = np.linalg.norm(q, axis=1)
                ok = np.isfinite(q).all(axis=1) & (np.abs(norm - 1.0) < 1e-3)
                rot[ok] = matrix_from_quat_wxyz(q[ok])
                p = x[:, pi].copy()
                p[~ok] = np.nan
                poses[s] = PoseSeries(p, rot)
            yield Block(_recording(self.name, ts - t_first, poses), np.full(n, now))

    def close(self) -> None:
        """Close the inlet."""
        with contextlib.suppress(Exception):
            self.inlet.close_stream()


def _lsl_lost_error(pylsl) -> type[BaseException]:
    """pylsl's ``LostError`` (``pylsl.util`` in pylsl 1.16+, the top level before)."""
    found = getattr(pylsl, "LostError", None)
    if found is None:
        from pylsl.util import LostError as found
    return found


def _format_name(code: int) -> str:
    """liblsl's channel format code -> its name (``float32``, ``string``, ...)."""
    names = {1: "float32", 2: "double64", 3: "string", 4: "int32", 5: "int16", 6: "int8"}
    return names.get(code, "int64" if code == 7 else f"format {code}")
