"""Where streamed frames go: LSL outlets, ROS 2 ``JointState`` over DDS, rosbag2, angles CSV.

* :class:`LslOutput` -- outlets ``PREFIX-angles`` (type ``JointAngles``, channels
  ``<digit>.<joint>`` in degrees) and ``PREFIX-tips`` (type ``MoCap``, channels
  ``<digit>.tip.x|y|z`` in millimetres), each followed by ``<digit>.source`` (0 from the
  digit's sensors, 1 solved by the model, 2 held) and a last channel ``valid``; double64;
  XDF channel metadata (label, unit, type); each sample stamped with its frame's arrival
  on the LSL clock. With ``--retarget``, a third outlet ``PREFIX-robot`` (type
  ``JointAngles``, one channel per robot joint, radians).
* :class:`Ros2Output` -- ``sensor_msgs/msg/JointState`` (radians, names
  ``<digit>_<joint>`` of the exported URDF, or the robot's joints with ``--retarget``) on
  the DDS topic ``rt/<topic>`` with the type name ``sensor_msgs::msg::dds_::JointState_``,
  final (XCDR1) types, reliable keep-last-10, domain ``ROS_DOMAIN_ID``; ``header.stamp`` =
  arrival on the system clock; beside it, ``<topic>/source``: a ``JointState`` whose
  names are the digits and whose positions say what each digit's values come from (0, 1,
  2 as above), published when it changes (reliable, keep last 1, transient local: a late
  subscriber gets the current one).
* :class:`BagOutput` -- the same messages in a rosbag2 (rosbags), written all-or-nothing.
* :class:`RecordOutput` -- the angles CSV ``fingerfit angles`` writes, all-or-nothing.
"""

from __future__ import annotations

import contextlib
import os
import re
import time
from pathlib import Path

import numpy as np

from ..errors import FingerfitError, shown
from ..transforms import FloatArray
from . import require

#: ROS 2 QoS depth of the publisher (a default ROS 2 publisher: reliable, keep last 10).
QOS_DEPTH = 10
_TOPIC_RE = re.compile(r"^/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$")


def dds_topic(topic: str) -> str:
    """ROS 2 topic -> DDS topic name: ``rt/`` + the name without its leading ``/``.

    Raises
    ------
    FingerfitError
        ``field '--ros2'``: not a valid ROS 2 topic name (letters, digits, ``_``,
        ``/`` separators; no token starting with a digit; no ``//``, no trailing ``/``).
    """
    if not _TOPIC_RE.match(topic):
        raise FingerfitError(
            f"'{shown(topic)}' is not a ROS 2 topic name (letters, digits, _ and / separators)",
            field="--ros2",
        )
    return "rt/" + topic.lstrip("/")


def ros_domain_id() -> int:
    """The DDS domain: ``ROS_DOMAIN_ID`` (0-232), 0 when unset or empty.

    Raises
    ------
    FingerfitError
        ``field 'ROS_DOMAIN_ID'``: not a whole number in 0-232.
    """
    raw = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not raw:
        return 0
    if not raw.isdigit() or int(raw) > 232:
        raise FingerfitError(
            f"'{shown(raw)}' is not a domain id 0-232 (environment variable)",
            field="ROS_DOMAIN_ID",
        )
    return int(raw)


def _new_folders(path: Path) -> list[Path]:
    """Folders above ``path`` that do not exist yet, deepest first."""
    return [q for q in Path(path).absolute().parents if not q.exists()]


def _remove_empty(folders: list[Path]) -> None:
    """Remove the folders a discarded output created (deepest first, only if empty)."""
    for q in folders:
        with contextlib.suppress(OSError):
            q.rmdir()


# -------------------------------------------------------------------------------- LSL


def _channel_info(info, channels: list[tuple[str, str, str]]) -> None:
    """XDF channel metadata: ``<channels><channel><label/><unit/><type/>``."""
    chans = info.desc().append_child("channels")
    for label, unit, kind in channels:
        ch = chans.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", unit)
        ch.append_child_value("type", kind)


class LslOutput:
    """LSL outlets: joint angles and fingertips, and the robot's joints when retargeting.

    Parameters
    ----------
    prefix : str
        Stream names ``<prefix>-angles``, ``<prefix>-tips`` (and ``<prefix>-robot``).
    angle_labels, tip_labels : list of str
        ``<digit>.<joint>`` and ``<digit>.tip.x|y|z`` (without ``valid``).
    rate_hz : float
        Nominal rate (0 for irregular).
    tips_frame : {"tracker", "hand"}
        Frame of the tips, stated in the stream description.
    source_id : str
        LSL source id stem (a consumer re-connects to the same source on restart).
    robot_labels : list of str, optional
        The robot's joint names: a third outlet ``<prefix>-robot`` (type ``JointAngles``).
    robot_units : list of str, optional
        Unit of each robot joint (``radians``; ``meters`` for a slide joint); default
        radians.
    robot_name : str
        The robot (stated in the stream description).
    source_labels : list of str, optional
        ``<digit>.source`` channels after the angles and after the tips
        (:attr:`fingerfit.live.values.Channels.source_labels`).
    """

    def __init__(
        self,
        prefix: str,
        angle_labels: list[str],
        tip_labels: list[str],
        rate_hz: float,
        tips_frame: str = "tracker",
        source_id: str = "fingerfit",
        robot_labels: list[str] | None = None,
        robot_units: list[str] | None = None,
        robot_name: str = "",
        source_labels: list[str] | None = None,
    ) -> None:
        pylsl = require("pylsl")
        self.pylsl = pylsl
        self.outlets = []
        self._rows: list[FloatArray] = []
        sources = [(lab, "code", "Source") for lab in source_labels or []]
        self._sources = len(sources)
        specs = [
            (
                f"{prefix}-angles",
                "JointAngles",
                [(lab, "degrees", "JointAngle") for lab in angle_labels] + sources,
            ),
            (
                f"{prefix}-tips",
                "MoCap",
                [(lab, "millimeters", "Position" + lab[-1].upper()) for lab in tip_labels]
                + sources,
            ),
        ]
        if robot_labels is not None:
            units = robot_units or ["radians"] * len(robot_labels)
            specs.append(
                (
                    f"{prefix}-robot",
                    "JointAngles",
                    [
                        (lab, u, "JointAngle" if u == "radians" else "JointPosition")
                        for lab, u in zip(robot_labels, units, strict=True)
                    ],
                )
            )
        for name, kind, channels in specs:
            channels = [*channels, ("valid", "boolean", "Valid")]
            info = pylsl.StreamInfo(
                name, kind, len(channels), rate_hz, pylsl.cf_double64, f"{source_id}-{name}"
            )
            _channel_info(info, channels)
            info.desc().append_child_value("tips_frame", tips_frame)
            info.desc().append_child_value("valid", "1 when every sensor of the frame was present")
            if sources and not name.endswith("-robot"):
                info.desc().append_child_value(
                    "source", "per digit: 0 from its sensors, 1 solved by the model, 2 held"
                )
            if name.endswith("-robot"):
                info.desc().append_child_value("robot", robot_name)
            self.outlets.append(pylsl.StreamOutlet(info, chunk_size=0, max_buffered=10))
            self._rows.append(np.empty((1, len(channels))))  # one sample, with valid
        # LSL clock = steady clock; arrival times are time.monotonic(): one offset.
        self.offset = pylsl.local_clock() - time.monotonic()
        self._first_consumer: float | None = None  # when one outlet first had a consumer

    #: Once one outlet has a consumer, how long (s) the others may take to get one too
    #: (a consumer may want only some of them; one that opens several opens them in turn).
    SECOND_CONSUMER_GRACE_S = 1.0

    def has_consumers(self) -> bool:
        """Whether every outlet has a consumer, or one has had one for
        :attr:`SECOND_CONSUMER_GRACE_S` (a consumer may want only the angles, the tips or
        the robot's joints)."""
        have = [o.have_consumers() for o in self.outlets]
        if all(have):
            return True
        if not any(have):
            self._first_consumer = None
            return False
        now = time.monotonic()
        if self._first_consumer is None:
            self._first_consumer = now
        return now - self._first_consumer >= self.SECOND_CONSUMER_GRACE_S

    def push(
        self,
        angles: FloatArray,
        tips: FloatArray,
        valid: FloatArray,
        arrival: FloatArray,
        robot: FloatArray | None = None,
        source: FloatArray | None = None,
    ) -> None:
        """Push frames.

        Parameters
        ----------
        angles : ndarray, shape (n, n_angles)
            Degrees.
        tips : ndarray, shape (n, n_tips)
            Millimetres.
        valid : ndarray, shape (n,)
            1.0 or 0.0.
        arrival : ndarray, shape (n,)
            ``time.monotonic()`` seconds; pushed as LSL timestamps.
        robot : ndarray, shape (n, n_robot_joints), optional
            The robot's joints (rad; m for a slide joint), when the outlet exists.
        source : ndarray, shape (n, n_digits), optional
            The ``<digit>.source`` codes (with ``source_labels``; default 0).
        """
        k = self._sources
        if k and source is None:
            source = np.zeros((valid.shape[0], k))
        values = (angles, tips) if robot is None else (angles, tips, robot)
        if valid.shape[0] == 1:  # the robot lane: one frame, into buffers allocated once
            stamp = float(arrival[0]) + self.offset  # one sample: its own stamp
            for i, (o, x, row) in enumerate(zip(self.outlets, values, self._rows, strict=True)):
                if k and i < 2:
                    row[0, : -1 - k] = x[0]
                    row[0, -1 - k : -1] = source[0]
                else:
                    row[0, :-1] = x[0]
                row[0, -1] = valid[0]
                o.push_chunk(row, stamp)
            return
        stamps = (arrival + self.offset).tolist()
        for i, (o, x) in enumerate(zip(self.outlets, values, strict=True)):
            parts = [x, source, valid] if k and i < 2 else [x, valid]
            o.push_chunk(np.column_stack(parts), stamps)

    #: How long (s) :meth:`close` lets connected consumers receive the last frames. liblsl
    #: sends from its own thread and drops what is still queued when an outlet is
    #: destroyed: without the wait, frames pushed in the last ~0.1 s were lost in every
    #: trial; 0.05 s lost none. liblsl has no flush to wait on.
    LINGER_S = 0.25

    def close(self) -> None:
        """Let connected consumers receive the last frames (:attr:`LINGER_S`), then drop the
        outlets (consumers see the stream end)."""
        if any(o.have_consumers() for o in self.outlets):
            time.sleep(self.LINGER_S)
        self.outlets.clear()


# ------------------------------------------------------------------------------ ROS 2


def joint_state_types():
    """The ROS 2 message types as cyclonedds IDL dataclasses (:mod:`.ros2types`).

    Returns
    -------
    Time, Header, JointState : type
        ``builtin_interfaces::msg::dds_::Time_``, ``std_msgs::msg::dds_::Header_``,
        ``sensor_msgs::msg::dds_::JointState_`` -- the DDS names rmw_cyclonedds uses.
    """
    require("cyclonedds")
    from . import ros2types

    return ros2types.Time, ros2types.Header, ros2types.JointState


def ros2_qos():
    """Reliable, keep-last-10 (a default ROS 2 publisher's QoS)."""
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration

    return Qos(
        Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
        Policy.History.KeepLast(QOS_DEPTH),
        Policy.Durability.Volatile,
    )


def source_qos():
    """The ``<topic>/source`` QoS: reliable, keep last 1, transient local (a subscriber
    that joins late gets the current message)."""
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration

    return Qos(
        Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
        Policy.History.KeepLast(1),
        Policy.Durability.TransientLocal,
    )


def stamp(seconds: float) -> tuple[int, int]:
    """System-clock seconds -> ``(sec, nanosec)`` of a ``builtin_interfaces/Time``."""
    ns = round(seconds * 1e9)
    return ns // 1_000_000_000, ns % 1_000_000_000


class Ros2Output:
    """A ``sensor_msgs/msg/JointState`` publisher over DDS (no ROS installation needed).

    Parameters
    ----------
    topic : str
        ROS 2 topic (``/hand/joint_states``); DDS topic ``rt/hand/joint_states``.
    names : list of str
        Joint names (``<digit>_<joint>``, :func:`fingerfit.export.geometry.joint_names`;
        with ``--retarget``, the robot's ``joint_names``).
    frame_id : str
        ``header.frame_id``.
    source_names : list of str, optional
        The digits: a second topic ``<topic>/source`` says what each digit's values come
        from (positions 0 from its sensors, 1 solved by the model, 2 held), published when
        it changes (:meth:`push_source`).
    """

    def __init__(
        self,
        topic: str,
        names: list[str],
        frame_id: str = "hand",
        source_names: list[str] | None = None,
    ) -> None:
        dds_name = dds_topic(topic)
        domain = ros_domain_id()
        require("cyclonedds")
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.pub import DataWriter
        from cyclonedds.topic import Topic

        self.Time, self.Header, self.JointState = joint_state_types()
        try:
            self.participant = DomainParticipant(domain)
        except Exception as exc:  # DDSException: bad CYCLONEDDS_URI, no network
            raise FingerfitError(
                f"cannot join DDS domain {domain}: {exc}", field="--ros2"
            ) from None
        qos = ros2_qos()
        self.topic = Topic(self.participant, dds_name, self.JointState, qos=qos)
        self.writer = DataWriter(self.participant, self.topic, qos=qos)
        self.names = list(names)
        self.frame_id = frame_id
        self.source_names = list(source_names or [])
        self._source: list[float] | None = None
        if self.source_names:
            sq = source_qos()
            self.source_topic = Topic(
                self.participant, f"{dds_name}/source", self.JointState, qos=sq
            )
            self.source_writer = DataWriter(self.participant, self.source_topic, qos=sq)

    def has_consumers(self) -> bool:
        """Whether a subscriber is matched."""
        return len(self.writer.get_matched_subscriptions()) > 0

    def message(self, positions: FloatArray, wall: float):
        """One ``JointState``: ``positions (n_joints,)`` rad, ``wall`` system-clock s."""
        sec, nsec = stamp(wall)
        return self.JointState(
            self.Header(self.Time(sec, nsec), self.frame_id),
            self.names,
            positions.tolist(),
            [],
            [],
        )

    def push(self, positions: FloatArray, wall: FloatArray) -> None:
        """Publish one message per frame: ``positions (n, n_joints)`` rad, ``wall (n,)`` s."""
        for p, w in zip(positions, wall.tolist(), strict=True):
            self.writer.write(self.message(p, w))

    def push_source(self, codes: FloatArray, wall: float) -> None:
        """Publish ``<topic>/source`` when the digits' source ``codes (n_digits,)`` changed
        since the last message (``wall``: system-clock s)."""
        if not self.source_names:
            return
        values = codes.tolist()
        if values == self._source:
            return
        self._source = values
        sec, nsec = stamp(wall)
        msg = self.JointState(
            self.Header(self.Time(sec, nsec), self.frame_id), self.source_names, values, [], []
        )
        self.source_writer.write(msg)

    def close(self) -> None:
        """Let matched readers acknowledge the last messages (up to 1 s), then delete the
        participant (and with it the writer)."""
        from cyclonedds.util import duration

        with contextlib.suppress(Exception):
            self.writer.wait_for_acks(duration(seconds=1))
        with contextlib.suppress(Exception):
            del self.writer, self.topic
        with contextlib.suppress(Exception):
            del self.source_writer, self.source_topic
        with contextlib.suppress(Exception):
            del self.participant


class BagOutput:
    """The ``JointState`` messages in a rosbag2 folder (sqlite3), written all-or-nothing.

    The folder appears when :meth:`close` succeeds; an error before removes the partial
    bag. Message timestamps are the frames' arrival on the system clock. The database is
    opened by the first :meth:`push` (or :meth:`close`): push and close on one thread.

    Parameters
    ----------
    path : Path
        Bag folder to create (must not exist, or be empty).
    topic : str
        ROS 2 topic of the connection (``/joint_states`` by default).
    names : list of str
    frame_id : str
    source_names : list of str, optional
        The digits: ``<topic>/source`` messages (:class:`Ros2Output`'s) are written when
        the digits' source changes (:meth:`push_source`).
    """

    def __init__(
        self,
        path: Path,
        topic: str,
        names: list[str],
        frame_id: str = "hand",
        source_names: list[str] | None = None,
    ) -> None:
        dds_topic(topic)  # the same name rules
        require("rosbags")
        from rosbags.rosbag2 import Writer
        from rosbags.typesys import Stores, get_typestore

        from ..io.atomic import staged_directory

        self.store = get_typestore(Stores.ROS2_HUMBLE)
        self._created = _new_folders(path)
        self._stage = staged_directory(path)
        staging = self._stage.__enter__()
        try:
            staging.rmdir()  # rosbags creates the folder itself
            try:
                self.writer = Writer(staging, version=8)
            except TypeError:  # rosbags < 0.10 has one bag version and no argument
                self.writer = Writer(staging)
        except BaseException as exc:
            with contextlib.suppress(FingerfitError):
                self._stage.__exit__(type(exc), exc, exc.__traceback__)
            _remove_empty(self._created)
            raise
        self.names = list(names)
        self.frame_id = frame_id
        self.topic = "/" + topic.lstrip("/")
        self.conn = None
        self.source_conn = None
        self.source_names = list(source_names or [])
        self._source: FloatArray | None = None
        t = self.store.types
        self._msg = t["sensor_msgs/msg/JointState"]
        self._header = t["std_msgs/msg/Header"]
        self._time = t["builtin_interfaces/msg/Time"]

    def _open(self) -> None:
        """Open the bag's database: on the thread that then writes and closes it (SQLite
        objects stay on the thread that made them; the stream's data lane is a thread of
        its own)."""
        if self.conn is None:
            self.writer.open()
            self.conn = self.writer.add_connection(
                self.topic, "sensor_msgs/msg/JointState", typestore=self.store
            )
            if self.source_names:
                self.source_conn = self.writer.add_connection(
                    f"{self.topic}/source", "sensor_msgs/msg/JointState", typestore=self.store
                )

    def push(self, positions: FloatArray, wall: FloatArray) -> None:
        """Write one message per frame (``positions (n, n_joints)`` rad, ``wall (n,)`` s)."""
        self._open()
        empty = np.zeros(0)
        for p, w in zip(positions, wall.tolist(), strict=True):
            sec, nsec = stamp(w)
            msg = self._msg(
                self._header(self._time(sec, nsec), self.frame_id),
                self.names,
                np.asarray(p, dtype=np.float64),
                empty,
                empty,
            )
            data = self.store.serialize_cdr(msg, "sensor_msgs/msg/JointState")
            self.writer.write(self.conn, sec * 1_000_000_000 + nsec, data)

    def push_source(self, codes: FloatArray, wall: FloatArray) -> None:
        """Write a ``<topic>/source`` message at every frame whose digits' source
        ``codes (n, n_digits)`` differs from the frame before (``wall (n,)`` s)."""
        if not self.source_names or not len(codes):
            return
        self._open()
        before = np.vstack(
            [self._source if self._source is not None else codes[:1] - 1, codes[:-1]]
        )
        changed = np.flatnonzero((codes != before).any(axis=1))
        empty = np.zeros(0)
        for i in changed:
            sec, nsec = stamp(float(wall[i]))
            msg = self._msg(
                self._header(self._time(sec, nsec), self.frame_id),
                self.source_names,
                np.asarray(codes[i], dtype=np.float64),
                empty,
                empty,
            )
            data = self.store.serialize_cdr(msg, "sensor_msgs/msg/JointState")
            self.writer.write(self.source_conn, sec * 1_000_000_000 + nsec, data)
        self._source = codes[-1].copy()

    def close(self, ok: bool = True) -> None:
        """Finish the bag and move it into place (``ok``) or remove it; on the thread that
        wrote it."""
        try:
            if ok:
                self._open()  # a bag of no message is still a bag
            if self.conn is not None:
                self.writer.close()
        except BaseException as exc:
            self._stage.__exit__(type(exc), exc, exc.__traceback__)
            raise
        if ok:
            self._stage.__exit__(None, None, None)
        else:
            err = FingerfitError("bag discarded")
            with contextlib.suppress(FingerfitError):
                self._stage.__exit__(FingerfitError, err, None)
            _remove_empty(self._created)


class RecordOutput:
    """The angles table of the streamed frames, what ``fingerfit angles`` writes for the
    same frames; appears complete at :meth:`close` (or not at all).

    A CSV, or for a ``.parquet`` path a Parquet file (:class:`fingerfit.io.parquet.ParquetSink`:
    each pushed block appended as a row group to a temporary file, renamed into place at
    :meth:`close`).

    Parameters
    ----------
    path : Path
    units : str
        Units of the fingertip columns (stated in a Parquet file's metadata).
    """

    def __init__(self, path: Path, units: str = "mm") -> None:
        from ..io.atomic import atomic_write
        from ..io.parquet import ParquetSink, angles_meta, is_parquet

        self._created = _new_folders(path)
        self._sink = ParquetSink(path, angles_meta(units)) if is_parquet(path) else None
        if self._sink is None:
            self._ctx = atomic_write(path, newline="")
            self._fh = self._ctx.__enter__()
        self._header = True
        self.rows = 0

    def push(self, table) -> None:
        """Append rows of :func:`fingerfit.kinematics.kinematics_table` (a DataFrame)."""
        if self._sink is not None:
            self._sink.write(table)
        else:
            table.to_csv(self._fh, index=False, lineterminator="\n", header=self._header)
        self._header = False
        self.rows += len(table)

    @property
    def started(self) -> bool:
        """Whether the header has been written."""
        return not self._header

    def close(self, ok: bool = True) -> None:
        """Rename the finished file into place (``ok``) or delete it."""
        if self._sink is not None:
            if not ok:
                self._sink.close(ok=False)
                _remove_empty(self._created)
                return
            self._sink.close()
            return
        if ok:
            self._ctx.__exit__(None, None, None)
        else:
            err = FingerfitError("record discarded")
            with contextlib.suppress(FingerfitError):
                self._ctx.__exit__(FingerfitError, err, None)
            _remove_empty(self._created)
