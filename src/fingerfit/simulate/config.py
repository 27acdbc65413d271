"""The switches and magnitudes of a simulated session (:class:`SimConfig`) and the true
hands it can be simulated from (:data:`WORLDS`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import FingerfitError

#: The true hands a session can be simulated from (``SimConfig.world``).
WORLDS = ("default", "myohand")


@dataclass(frozen=True)
class SimConfig:
    """Switches and magnitudes of a simulated session.

    Every error source can be switched off; :meth:`exact` gives the noise-free,
    pure-hinge configuration used to check exactness.

    Attributes
    ----------
    fingers : tuple of str
        Digits: any of ``thumb``, ``index``, ``middle``, ``ring``, ``little``. The thumb
        adds its own recordings (:mod:`.wholehand`) and draws everything from its own
        generator, so the fingers' truth does not depend on it.
    hand : {"left", "right"}
    rate_hz : float
    noise : float
        Tracker error scale (white noise and field distortion); 1 = Liberty-like.
    distortion : bool
        Smooth field distortion on/off (scaled by ``noise``).
    sta : float
        Soft-tissue artefact scale (1 = realistic, 0 = rigid sensors).
    stylus_mm : float
        Stylus noise SD per axis (mm).
    tilt_scale : float
        Axis obliquity scale (1 = literature; 0 = axes perpendicular to bones).
    rolling : bool
        Centre of rotation migrating with flexion.
    abduction : bool
        MP ab/adduction axis moving during grasp and free motion (the thumb's MCP
        ab/adduction likewise; its CMC always has two axes).
    abduction_coupling : tuple of float
        MP ab/adduction per radian of MP flexion (rad/rad): mean and SD over subjects and
        fingers (drawn per finger).
    abduction_wander_deg, abduction_wander_hz : float
        The MP ab/adduction independent of flexion during the grasp cycles: SD (deg) and
        the highest frequency (Hz) of its slow wander (frequencies from 0.05 Hz up).
    thumb_mcp_abduction : {"every", "contact"}
        Recordings in which the thumb's MCP ab/adducts (with ``abduction``): ``every``
        one, or only the opposition and pinch recordings (and free motion).
    rom_scale : float
        Grasp range-of-motion scale.
    cycles : int
        Grasp cycles.
    targets, test : bool
        Include the target-reaching and free-motion recordings.
    world : {"default", "myohand"}
        The true hand: fingerfit's own anatomy (:mod:`.anatomy`, :mod:`.thumb`) or the
        MyoHand model's fingers and thumb (:mod:`.myohand`: right hand, fixed axes, so
        ``rolling`` has no effect there, and a hinge thumb MCP; ``tilt_scale`` scales its
        per-subject axis scatter).
    mp_axis_tilt_deg : float, optional
        Sets every finger's MP flexion-axis obliquity off perpendicular to the bone (deg,
        about the finger's dorsal axis z: positive turns the axis's +y end distally) in
        place of the drawn one; the dorsal tilt and everything else are drawn as usual.
        ``None`` (default): the drawn obliquity, every output as without the field.
        Default world only; ``|value| < 60``.
    stylus_recordings : bool
        Also simulate the stylus: a pivot calibration recording and the stylus recording
        of the session's landmarks (:mod:`.stylus`), from their own random stream (the
        session is the same with or without them).
    """

    fingers: tuple[str, ...] = ("index",)
    hand: str = "left"
    rate_hz: float = 240.0
    noise: float = 1.0
    distortion: bool = True
    sta: float = 1.0
    stylus_mm: float = 0.3
    tilt_scale: float = 1.0
    rolling: bool = True
    abduction: bool = True
    abduction_coupling: tuple[float, float] = (-0.07, 0.04)
    abduction_wander_deg: float = 1.0
    abduction_wander_hz: float = 0.3
    thumb_mcp_abduction: str = "every"
    rom_scale: float = 1.0
    cycles: int = 10
    targets: bool = True
    test: bool = True
    world: str = "default"
    mp_axis_tilt_deg: float | None = None
    stylus_recordings: bool = False

    def __post_init__(self) -> None:
        if self.world not in WORLDS:
            raise FingerfitError(
                f"must be one of {', '.join(WORLDS)}, not {self.world!r}", field="--world"
            )
        tilt = self.mp_axis_tilt_deg
        if tilt is not None:
            if not (np.isfinite(tilt) and abs(tilt) < 60.0):
                raise FingerfitError(
                    f"must be a finite angle below 60 deg in magnitude, not {tilt!r}",
                    field="mp_axis_tilt_deg",
                )
            if self.world != "default":
                raise FingerfitError(
                    "the MP axis tilt is an option of the default world only",
                    field="mp_axis_tilt_deg",
                )

    @classmethod
    def exact(cls, **kw) -> SimConfig:
        """Noise-free, rigid sensors, pure hinges: the model is exactly right."""
        base = dict(
            noise=0.0, distortion=False, sta=0.0, stylus_mm=0.0, rolling=False, abduction=False
        )
        base.update(kw)
        return cls(**base)
