"""fingerfit: individual skeletal finger models from 6-DOF motion capture.

Data flows one way: files -> :class:`~fingerfit.session.Session` -> estimation
(:mod:`fingerfit.estimate`) -> :class:`~fingerfit.model.DigitModel` ->
kinematics (:mod:`fingerfit.kinematics`) -> evaluation, report and export.
Frames, units and quaternion order are defined once, in ``docs/conventions.md``.
"""

__version__ = "0.1.0"
