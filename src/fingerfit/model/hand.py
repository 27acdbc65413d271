"""The individual hand model (five digits at most): joints, segment frames, digits, pinch
contacts, and the geometry made from them (orthogonal axes, a digit assembled from its
fit, the pad point estimated from the tip).

Everything geometric is in **tracker coordinates at the reference posture, in mm** (and,
for each joint, also in its parent sensor's frame). See ``docs/conventions.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .. import __version__
from ..digits import DIGITS, second_axis
from ..transforms import FloatArray
from .tracking import TrackingStats

VARIANTS = ("user_axis", "orthogonal")
# How joint angles are computed from the sensors (``docs/methods.md``): the paper's
# projection of the child sensor origin (Fig. 6) or the swing-twist decomposition of the
# full relative orientation. Files written before this field existed used "projection".
ANGLE_METHODS = ("projection", "swing_twist")


@dataclass(frozen=True)
class JointQuality:
    """How well the motion determined a joint (paper Fig. 8 and conditioning).

    Attributes
    ----------
    cycles : int
        Movement periods used.
    rom_deg : list of float
        Range of motion of each cycle (deg).
    centre_distance_mm : list of float
        Distance of each cycle's centre of rotation to the fitted axis (mm).
    conditioning : list of float
        ``s5/s6`` of each cycle's centre-of-rotation system.
    spread_mm : float
        RMS spread of the cycle centres along the axis (mm).
    residual_mm : list of float
        Residual RMS of each cycle's centre fit (mm).
    null_agreement_deg : float
        Angle between the fitted axis and the cycles' own rotation axis (SVD null
        vectors); large means the centres did not spread along the axis.
    notes : list of str
        Warnings recorded while fitting.
    pooled_conditioning : float or None
        ``s5/s6`` of the pooled system over all kept movement frames (pooled
        methods): RMS rotation about the axis over RMS rotation off it.
    rejected_frames : int
        Movement frames rejected as outliers (robust methods).
    rejected_cycles : list of int
        Indices (0-based, in extraction order) of cycles rejected as inconsistent.
    model_choice : dict or None
        A joint that may have a second axis (a finger's MP, the thumb's MCP): the choice
        between one and two axes by held-out prediction
        (:meth:`fingerfit.estimate.choice.ModelChoice.summary`: ``chosen``,
        ``held_out_hinge_mm``, ``held_out_two_axis_mm``, ``folds``,
        ``two_axis_candidate``).
    axis_ci_deg : float or None
        95 % confidence half-angle of the flexion axis from its spread over the cycles
        (deg; :func:`fingerfit.estimate.fit.axis_ci_deg`, the figure ``fingerfit capture``
        shows). None: not known (fewer than two cycles, or a file written before it).
    """

    cycles: int
    rom_deg: list[float]
    centre_distance_mm: list[float]
    conditioning: list[float]
    spread_mm: float
    residual_mm: list[float]
    null_agreement_deg: float = 0.0
    notes: list[str] = field(default_factory=list)
    pooled_conditioning: float | None = None
    rejected_frames: int = 0
    rejected_cycles: list[int] = field(default_factory=list)
    model_choice: dict | None = None
    axis_ci_deg: float | None = None


@dataclass(frozen=True)
class JointModel:
    """One flexion joint at the reference posture (tracker coordinates, mm).

    Attributes
    ----------
    name : str
        A flexion joint (``mp``, ``pip``, ``dip``; the thumb's ``cmc``, ``mcp``, ``ip``)
        or a second axis (``<joint>_abduction``).
    parent, child : str
        Sensor names on the two segments.
    center : ndarray, shape (3,)
        Joint centre (on the sagittal plane).
    axis : ndarray, shape (3,)
        Fitted ("user") axis, unit, oriented so flexion (ab/adduction: radial or, for
        the thumb, palmar abduction; ``docs/conventions.md``) is positive.
    orthogonal_axis : ndarray, shape (3,)
        The axis of the classic model robot hands use: a flexion axis made perpendicular
        to the bone; a second axis perpendicular to the bone and to the orthogonal
        flexion axis.
    quality : JointQuality
    migration : ndarray, shape (3,), optional
        Rolling-contact migration of the centre (mm/rad, tracker coordinates at
        the reference posture): at angle ``theta`` the joint turns about the line
        through ``center + theta * migration``. ``None``: a fixed centre.
    """

    name: str
    parent: str
    child: str
    center: FloatArray
    axis: FloatArray
    orthogonal_axis: FloatArray
    quality: JointQuality
    migration: FloatArray | None = None

    def axis_for(self, variant: str) -> FloatArray:
        """Axis ``(3,)`` of the ``user_axis`` or ``orthogonal`` variant."""
        return self.axis if variant == "user_axis" else self.orthogonal_axis


@dataclass(frozen=True)
class SegmentFrame:
    """A segment's local frame (paper Fig. 4): origin at its distal end, x along the bone,
    ``z = x × a``, ``y = z × x``. ``rotation`` columns are x, y, z in tracker coordinates."""

    origin: FloatArray
    rotation: FloatArray


@dataclass(frozen=True)
class DigitModel:
    """One digit: three flexion joints, second axes, tip and pad points, segment lengths
    and frames (mm, tracker coordinates at the reference posture).

    Attributes
    ----------
    name : str
        ``thumb``, ``index``, ``middle``, ``ring`` or ``little`` (:mod:`fingerfit.digits`).
    joints : dict[str, JointModel]
        The flexion joints, proximal to distal: ``mp``, ``pip``, ``dip`` (the thumb:
        ``cmc``, ``mcp``, ``ip``).
    tip : ndarray, shape (3,)
        Tip point (nail-edge landmark).
    segment_lengths : dict[str, float]
        Per segment (``proximal``, ``middle``, ``distal``; the thumb: ``metacarpal``,
        ``proximal``, ``distal``), mm, centre to centre / to the tip.
    frames : dict[str, SegmentFrame]
    second_axes : dict[str, JointModel]
        Flexion joint -> its second (ab/adduction) axis ``<joint>_abduction`` (same
        parent and child sensors), for two-axis joints only. Which of the two axes is
        proximal is :meth:`order` (:mod:`fingerfit.digits`): a finger's MP turns about
        the ab/adduction axis proximally, ``tip = Rot_ab(Rot_mp(Rot_pip(Rot_dip(tip))))``;
        the thumb's CMC and MCP about the flexion axis proximally, all about fixed
        reference-posture lines.
    pad : ndarray, shape (3,), optional
        Pad point: the centre of the pulp's contact area on the palmar skin
        (``docs/conventions.md``, "Pads"), carried by the distal segment; ``None`` in models
        written before pads existed.
    axis_order : dict[str, str]
        Two-axis joints whose axes the fit found in the other order than the digit's
        usual one (:mod:`fingerfit.digits`): joint -> ``abduction_first`` or
        ``flexion_first``. Empty for most models (:meth:`order`).
    pad_source : {"pinch", "landmark", "geometry"}, optional
        Where :attr:`pad` comes from: the session's pinch holds
        (:mod:`fingerfit.estimate.pads`), the digitised ``<digit>.pad`` landmark, or the
        pulp geometry of :func:`estimated_pad`; ``None`` in models written before the
        field existed.
    tip_sd_mm : float, optional
        The tip point's uncertainty (mm): the standard error of the stylus takes that
        digitised it (``landmarks.csv``'s ``sd``); ``None`` when not known.
    """

    name: str
    joints: dict[str, JointModel]
    tip: FloatArray
    segment_lengths: dict[str, float]
    frames: dict[str, SegmentFrame]
    second_axes: dict[str, JointModel] = field(default_factory=dict)
    pad: FloatArray | None = None
    pad_source: str | None = None
    axis_order: dict[str, str] = field(default_factory=dict)
    tip_sd_mm: float | None = None

    @property
    def segments(self) -> tuple[str, str, str]:
        """Segment names, proximal to distal."""
        return DIGITS[self.name].segments

    def order(self, joint: str) -> str:
        """``abduction_first`` or ``flexion_first``: which axis of a two-axis joint is
        proximal (:attr:`axis_order` where the fit chose it, else the digit's)."""
        return self.axis_order.get(joint) or DIGITS[self.name].order[joint]

    def axes(self, joint: str) -> list[JointModel]:
        """The axes of ``joint``, proximal first (one for a hinge, two for a two-axis joint)."""
        first = self.joints[joint]
        second = self.second_axes.get(joint)
        if second is None:
            return [first]
        return [second, first] if self.order(joint) == "abduction_first" else [first, second]

    def chain(self, depth: int = 3) -> list[JointModel]:
        """Every axis of the first ``depth`` joints, proximal to distal (:meth:`axes` of
        each joint in turn): the order of the robot joints and, reversed, of the turns
        that move a point of the distal segment."""
        return [jm for j in list(self.joints)[:depth] for jm in self.axes(j)]

    def angle_names(self) -> tuple[str, ...]:
        """Angle names of the digit: flexion joints, then ``<joint>_abduction`` of each
        two-axis joint (the angles CSV's column order)."""
        return DIGITS[self.name].angle_names(tuple(self.second_axes))


#: Where a digit's pad point comes from (:attr:`DigitModel.pad_source`).
PAD_SOURCES = ("pinch", "landmark", "geometry")


@dataclass(frozen=True)
class PinchContact:
    """How close two digits' model pads come while they touch, from the person's own
    pinch holds in the session the model was fitted from.

    Attributes
    ----------
    digits : tuple of (str, str)
        The two digits, in the order of :data:`fingerfit.digits.DIGIT_NAMES` (the events
        may name them either way).
    events, frames : int
        Pinch events of the pair and their hold frames.
    contact_mm : dict[str, float]
        Variant (``user_axis``, ``orthogonal``) -> the largest over the pair's holds of the
        95th percentile over the hold's frames of the distance between the two digits'
        pads as the model computes them (:mod:`fingerfit.kinematics`), with the pads
        fitted to every hold and without that hold
        (:func:`fingerfit.estimate.pads.pinch_pads`), mm: below it the person's pads
        touch (``fingerfit retarget``'s pinch term).
    """

    digits: tuple[str, str]
    events: int
    frames: int
    contact_mm: dict[str, float]


@dataclass(frozen=True)
class HandModel:
    """An individual hand model: what ``fingerfit fit`` writes.

    Attributes
    ----------
    subject, hand : str
    session_units : str
        Units of the session it was fitted from (outputs use them).
    method : str
    reference_poses : dict[str, tuple[ndarray, ndarray]]
        Sensor name -> (position ``(3,)`` mm, rotation ``(3, 3)`` sensor -> tracker)
        at the reference posture.
    fingers : dict[str, DigitModel]
        Digit name -> model (the thumb included; the JSON key is ``fingers``).
    version : str
        fingerfit version that wrote it.
    angle_method : {"projection", "swing_twist"}
        How :mod:`fingerfit.kinematics` computes joint angles from the sensors
        (files without the field: ``projection``, the paper's method).
    warnings : tuple of str
        Plausibility and quality warnings the fit was forced past (``--force``);
        stored in the model file (``"warnings"``, absent or empty when none) and shown
        in the report.
    pinch_contacts : tuple of PinchContact
        Per pair of digits that pinched in the session, how close their pads come while
        touching (``"pinch_contacts"`` in the file; empty without pinch events).
    tracking : TrackingStats, optional
        Each sensor's spread about the model and each angle's range in the calibration
        recordings (``"tracking"`` in the file), which tracking with fewer sensors needs
        (:mod:`fingerfit.track`); ``None`` in files written before it existed.
    markers : dict[str, tuple[str, ndarray, ndarray]]
        A model fitted from skin markers (:mod:`fingerfit.estimate.markers`): marker
        label -> (its segment's sensor name, ``hand`` or ``<digit>.<segment>``; its place
        ``(3,)`` at the reference posture, mm, tracker coordinates; its skin slide
        ``(3,)`` per radian of the segment's proximal flexion, mm/rad, 0 where not
        estimated). Empty for a model fitted from 6-DOF sensors.
    """

    subject: str
    hand: str
    session_units: str
    method: str
    reference_poses: dict[str, tuple[FloatArray, FloatArray]]
    fingers: dict[str, DigitModel]
    version: str = __version__
    angle_method: str = "projection"
    warnings: tuple[str, ...] = ()
    pinch_contacts: tuple[PinchContact, ...] = ()
    tracking: TrackingStats | None = None
    markers: dict[str, tuple[str, FloatArray, FloatArray]] = field(default_factory=dict)

    def pinch_contact(self, a: str, b: str) -> PinchContact | None:
        """The :class:`PinchContact` of digits ``a`` and ``b`` (either order), or None."""
        return next((c for c in self.pinch_contacts if set(c.digits) == {a, b}), None)

    def in_parent(
        self, finger: str, joint: str, variant: str = "user_axis"
    ) -> tuple[FloatArray, FloatArray]:
        """Centre ``(3,)`` mm and axis ``(3,)`` of a joint or second axis (by its name,
        e.g. ``pip`` or ``mp_abduction``) in the parent sensor's frame."""
        j = self.axis(finger, joint)
        p, r = self.reference_poses[j.parent]
        return r.T @ (j.center - p), r.T @ j.axis_for(variant)

    def axis(self, finger: str, name: str) -> JointModel:
        """A digit's joint or second axis by name (``pip``, ``cmc_abduction``, ...)."""
        fm = self.fingers[finger]
        if name in fm.joints:
            return fm.joints[name]
        for j, second in fm.second_axes.items():
            if second_axis(j) == name:
                return second
        raise KeyError(f"{finger} has no axis '{name}'")


def with_fixed_centres(model: HandModel) -> tuple[HandModel, dict[str, float]]:
    """The model with every migrating joint centre fixed at its mid-range position.

    A rolling-contact joint's centre moves as ``c + theta * m``; a revolute joint
    (robot software) needs a fixed one. The centre is fixed at the middle of the
    observed range, ``theta = max(rom_deg) / 2``, which halves the largest
    displacement over that range.

    Parameters
    ----------
    model : HandModel

    Returns
    -------
    model : HandModel
        A copy without migration (unchanged joints are shared).
    deviation_mm : dict[str, float]
        ``"<finger>.<joint>"`` -> the largest distance (mm) between the fixed and the
        migrating centre over the observed range (only joints that migrated).
    """
    fingers, deviation = {}, {}
    for fname, fm in model.fingers.items():
        joints = dict(fm.joints)
        for j, jm in fm.joints.items():
            if jm.migration is None:
                continue
            half = 0.5 * math.radians(max(jm.quality.rom_deg, default=0.0))
            joints[j] = replace(jm, center=jm.center + half * jm.migration, migration=None)
            deviation[f"{fname}.{j}"] = float(half * np.linalg.norm(jm.migration))
        fingers[fname] = replace(fm, joints=joints)
    return replace(model, fingers=fingers), deviation


def orthogonal_axis(axis: FloatArray, bone: FloatArray) -> FloatArray:
    """``axis (3,)`` made perpendicular to the unit ``bone (3,)`` direction (unit ``(3,)``)."""
    y = axis - (axis @ bone) * bone
    return y / np.linalg.norm(y)


def orthogonal_second_axis(axis: FloatArray, flexion: FloatArray, bone: FloatArray) -> FloatArray:
    """A second axis ``(3,)`` of the orthogonal model: perpendicular to the unit ``bone``
    and to the orthogonal ``flexion`` axis ``(3,)``, with the sense of ``axis (3,)``."""
    y = np.cross(flexion, bone)
    y /= np.linalg.norm(y)
    return y if y @ axis >= 0 else -y


def assemble_digit(
    name: str,
    joints: dict[str, tuple[str, str, FloatArray, FloatArray, JointQuality]],
    tip: FloatArray,
    second_axes: dict[str, JointModel] | None = None,
    migration: dict[str, FloatArray] | None = None,
    pad: FloatArray | None = None,
) -> DigitModel:
    """Segment lengths, local frames and orthogonal axes of a digit from its joints.

    Parameters
    ----------
    name : str
        Digit name (:data:`fingerfit.digits.DIGIT_NAMES`).
    joints : dict
        The digit's three flexion joints, proximal to distal (``mp``, ``pip``, ``dip``;
        ``cmc``, ``mcp``, ``ip``) -> ``(parent, child, centre (3,), axis (3,), quality)``;
        centres (mm) and unit axes (oriented so flexion is positive) in tracker
        coordinates at the reference posture.
    tip : ndarray, shape (3,)
        Tip landmark (mm, same frame).
    second_axes : dict, optional
        Flexion joint -> its second axis (``orthogonal_axis`` is recomputed here).
    migration : dict, optional
        Joint -> centre migration ``(3,)`` mm/rad (tracker frame at the reference posture).
    pad : ndarray, shape (3,), optional
        Pad point (mm, same frame).

    Returns
    -------
    DigitModel
        Bones run centre to centre (and from the last centre to the tip); the
        orthogonal axis of each flexion joint is its axis made perpendicular to the bone
        of the segment ending at it (for the first joint the bone it moves: a finger's
        metacarpal is taken collinear with the proximal phalanx, the thumb's CMC moves
        the metacarpal); a second axis's orthogonal axis is perpendicular to that bone
        and to the orthogonal flexion axis. The local frame of each segment is the
        paper's Fig. 4 frame at its distal end.
    """
    names = DIGITS[name].joints
    ends = [joints[j][2] for j in names] + [tip]
    bones = [(ends[i + 1] - ends[i]) / np.linalg.norm(ends[i + 1] - ends[i]) for i in range(3)]
    bone_at = {names[0]: bones[0], names[1]: bones[0], names[2]: bones[1]}
    migration = migration or {}
    out: dict[str, JointModel] = {}
    for j in names:
        parent, child, c, a, quality = joints[j]
        out[j] = JointModel(
            j, parent, child, c, a, orthogonal_axis(a, bone_at[j]), quality, migration.get(j)
        )
    seconds = {
        j: replace(
            jm, orthogonal_axis=orthogonal_second_axis(jm.axis, out[j].orthogonal_axis, bone_at[j])
        )
        for j, jm in (second_axes or {}).items()
    }
    frames = {}
    axes_at_end = [out[names[1]].axis, out[names[2]].axis, out[names[2]].axis]
    for i, s in enumerate(DIGITS[name].segments):
        x = bones[i]
        z = np.cross(x, axes_at_end[i])
        z /= np.linalg.norm(z)
        frames[s] = SegmentFrame(ends[i + 1], np.column_stack([x, np.cross(z, x), z]))
    lengths = {
        s: float(np.linalg.norm(ends[i + 1] - ends[i])) for i, s in enumerate(DIGITS[name].segments)
    }
    return DigitModel(name, out, tip, lengths, frames, seconds, pad)


#: Where the pad point lies on the distal segment when no ``<digit>.pad`` landmark was
#: digitised: this fraction of the distal segment's length proximal of the tip.
PAD_FROM_TIP = 0.25


def estimated_pad(digit: DigitModel, thickness: float) -> FloatArray:
    """The pad point ``(3,)`` of a digit without a digitised ``<digit>.pad`` landmark (mm).

    Parameters
    ----------
    digit : DigitModel
        Its tip (nail edge, dorsal), distal segment frame and length at the reference
        posture (tracker coordinates, mm).
    thickness : float
        The digit's thickness at its distal segment (mm), e.g. twice the height of the
        last joint's dorsal landmark above that joint's centre.

    Returns
    -------
    ndarray, shape (3,)
        The tip moved palmar by ``thickness`` (along ``-z`` of the distal segment frame,
        ``z`` being dorsal) and proximal by :data:`PAD_FROM_TIP` of the distal segment's
        length: an approximation of the pulp's contact centre on the skin
        (``docs/conventions.md``); a digitised pad landmark is better.
    """
    frame = digit.frames[digit.segments[-1]].rotation
    x, z = frame[:, 0], frame[:, 2]
    length = digit.segment_lengths[digit.segments[-1]]
    return digit.tip - thickness * z - PAD_FROM_TIP * length * x
