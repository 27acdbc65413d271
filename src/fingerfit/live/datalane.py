"""The data lane of a stream: every frame, in vectorised blocks on its own thread, to the
files (``--record``, ``--ros2-bag``) and the live view (:mod:`.stream`)."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import pandas as pd

from ..kinematics import KinematicsPlan, kinematics_table
from ..model import HandModel
from ..track.recording import last_frame, track_recording
from ..track.report import tracking_columns
from ..transforms import FloatArray
from .markers import is_marker_model, kinematics_of, with_hand
from .outputs import BagOutput, RecordOutput
from .sources import MAX_BLOCK, Block
from .values import (
    Channels,
    Summary,
    _join,
    block_values,
    concat_blocks,
    empty_recording,
    hold,
    sensor_presence,
    source_codes,
)

#: Seconds between the data lane's passes over what is queued.
DATA_PERIOD = 0.05


class DataLane:
    """Every frame to the files (``--record``, ``--ros2-bag``) and the view (``--view``,
    ``--view-save``), on a thread of its own.

    Blocks are queued as they arrive (:meth:`put`); the thread takes everything queued
    every :data:`DATA_PERIOD` s and computes it as one block (at most
    :data:`~fingerfit.live.sources.MAX_BLOCK` frames at a time) -- so a backlog costs one
    vectorised pass, not one per frame -- and writes it. :meth:`finish` writes what is
    still queued and stops the thread: then ``summary.recorded`` = every frame put.

    Parameters
    ----------
    model : HandModel
    summary : Summary
        Where ``recorded``, ``data_compute``, ``data_sizes`` and ``data_lag`` go.
    record : RecordOutput, optional
    bag : BagOutput, optional
    record_units : str
    channels : Channels
    sensors : list of str
    retargeter : fingerfit.retarget.Retargeter, optional
        The bag's and the view's robot joints (its own instance: its warm start follows
        every frame).
    view : fingerfit.view.LiveView, optional
        Gets every block's frames (and the robot's joints, with a ``retargeter``), after
        the files: a hand-off to the view's own process, which computes and logs them
        (``summary.view_dropped`` and ``view_logged`` count what it dropped and logged).
    wall_offset : float
        System clock minus ``time.monotonic()`` (s), for the bag's stamps.
    """

    def __init__(
        self,
        model: HandModel,
        summary: Summary,
        *,
        record: RecordOutput | None,
        bag: BagOutput | None,
        record_units: str,
        channels: Channels,
        sensors: list[str],
        retargeter: Any = None,
        wall_offset: float = 0.0,
        view: Any = None,
    ) -> None:
        self.model, self.summary = model, summary
        self.record, self.bag, self.view = record, bag, view
        self.record_units = record_units
        self.channels, self.sensors = channels, sensors
        self.retargeter = retargeter if bag is not None or view is not None else None
        # The angles CSV has both models' tips; the view computes its own, in its process.
        variants = ["user_axis"] + (["orthogonal"] if record is not None else [])
        if self.retargeter is not None and self.retargeter.variant not in variants:
            variants.append(self.retargeter.variant)
        self.variants = tuple(variants)
        # Only the view: no kinematics here at all.
        self.computes = record is not None or bag is not None or self.retargeter is not None
        self.plan = (
            KinematicsPlan(model, self.variants)
            if model.angle_method == "swing_twist" and not is_marker_model(model)
            else None
        )
        self.wall_offset = wall_offset
        self._queue: list[Block] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._last: FloatArray | None = None
        self.solves = model.tracking is not None
        self.markers = is_marker_model(model)
        self._anchor = None  # the last frame written: the next block's temporal anchor
        self.error: BaseException | None = None
        self.ok = True
        self._thread = threading.Thread(target=self._run, name="fingerfit-data-lane", daemon=True)
        self._thread.start()

    @property
    def thread(self) -> threading.Thread:
        """The lane's thread (``--realtime`` keeps it off the robot lane's CPU)."""
        return self._thread

    def put(self, block: Block) -> None:
        """Queue a block (cheap: the thread computes it)."""
        with self._lock:
            self._queue.append(block)

    def backlog(self) -> int:
        """Frames queued and not yet written."""
        with self._lock:
            return sum(b.recording.n_frames for b in self._queue)

    def _take(self) -> list[Block]:
        with self._lock:
            blocks, self._queue = self._queue, []
        return blocks

    def _run(self) -> None:
        ok = False
        try:
            while not self._stop.wait(DATA_PERIOD):
                self._write(self._take())
            ok = self.ok
            if ok:
                self._write(self._take())  # what came before the stop
                if self.record is not None and not self.record.started:
                    # No frame at all: still a complete CSV (an empty recording's header).
                    variants = ("user_axis", "orthogonal")
                    empty = empty_recording(self.sensors, is_marker_model(self.model))
                    kin = kinematics_of(self.model, empty, variants)[0]
                    self.record.push(self._table(kin, None))
        except BaseException as exc:  # handed to the loop, which raises it
            self.error, ok = exc, False
        # The files are closed on this thread (a bag's SQLite objects belong to it).
        for o in (self.record, self.bag, self.view):
            if o is not None:
                try:
                    o.close(ok)
                except BaseException as exc:
                    self.error = self.error or exc
        if self.view is not None:
            self.summary.view_logged = self.view.logged
            self.summary.view_dropped = self.view.dropped

    def _write(self, blocks: list[Block]) -> None:
        if not blocks:
            return
        block = concat_blocks(blocks)
        n = block.recording.n_frames
        for i in range(0, n, MAX_BLOCK):
            part = Block(
                block.recording.slice(slice(i, i + MAX_BLOCK)), block.arrival[i : i + MAX_BLOCK]
            )
            self._write_one(part)

    def _write_one(self, block: Block) -> None:
        rec, s = block.recording, self.summary
        t = time.perf_counter()
        presence = sensor_presence(rec, self.sensors)
        complete = bool(presence.all())
        kin = tracked = None
        if not self.computes:
            pass
        elif not complete and self.solves and rec.n_frames:
            # Frames with a missing sensor: solved by the model as `fingerfit angles` does,
            # joined to the previous block by the temporal prior.
            tracked = track_recording(self.model, rec, self.variants, anchor=self._anchor)
            kin = tracked.kinematics
        elif self.plan is not None and rec.n_frames:
            kin = self.plan.run(rec)
        else:
            kin, unconverged = kinematics_of(self.model, rec, self.variants)
            s.data_unconverged += unconverged
        if kin is not None and rec.n_frames and self.solves:
            self._anchor = last_frame(kin)
        joints = robot = None
        source = (
            None
            if complete
            else source_codes(presence, self.sensors, self.model, self.channels.digits, self.solves)
        )
        if self.retargeter is not None:
            fed = with_hand(self.model, rec, kin) if self.markers else (rec, kin)
            robot = self.retargeter.step(*fed)[0]
        if self.bag is not None:
            if robot is not None:
                joints = robot
            else:
                joints = block_values(kin, self.channels, rec, self.sensors, "tracker").joints
        compute = time.perf_counter() - t
        if self.record is not None:
            self.record.push(self._table(kin, tracked))
        if joints is not None and self.bag is not None:
            last = self._last if self._last is not None else np.full(joints.shape[1], np.nan)
            if joints.size and not np.isfinite(joints).all():
                joints = hold(joints, last)
            if joints.shape[0]:
                self._last = joints[-1]
            wall = block.arrival + self.wall_offset
            self.bag.push(joints, wall)
            codes = (
                source
                if source is not None
                else np.zeros((rec.n_frames, len(self.channels.digits)))
            )
            self.bag.push_source(codes, wall)
        if self.view is not None:
            self.view.push(rec, robot)
            s.view_dropped = self.view.dropped
        if self.computes:  # (a view alone computes nothing here: no time to report)
            s.data_compute.append(compute)
            s.data_sizes.append(rec.n_frames)
        if len(s.data_compute) >= 4096:
            s.data_compute = [_join(s.data_compute)]
            s.data_sizes = [_join(s.data_sizes)]
        if rec.n_frames:
            s.data_lag = max(s.data_lag, time.monotonic() - float(block.arrival[0]))
        s.recorded += rec.n_frames

    def _table(self, kin, tracked) -> pd.DataFrame:
        """The record's rows: the angles table, with the columns ``fingerfit angles`` adds
        for a model that can solve frames (``<digit>.ik_rms_mm``, empty where direct)."""
        table = kinematics_table(kin, units=self.record_units)
        if not self.solves:
            return table
        n = kin.time.shape[0]
        extra = (
            tracking_columns(tracked)
            if tracked is not None
            else {f"{d}.ik_rms_mm": np.full(n, np.nan) for d in kin.motions["user_axis"]}
        )
        return pd.concat([table, pd.DataFrame(extra)], axis=1)

    def finish(self, ok: bool = True) -> None:
        """Write every queued frame (``ok``; else discard them), close the files (kept
        when ``ok``) and stop the thread; raise its error, if any (the files are then
        removed)."""
        self.ok = ok
        self._stop.set()
        self._thread.join()
        if self.error is not None:
            raise self.error
