"""Estimation of joint centres and axes from 6-DOF sensor recordings.

* :mod:`.cycles` -- per-joint grasp-cycle extraction (movement periods);
* :mod:`.centre` -- centre of rotation from two 6-DOF sensors (O'Brien et al. 2000);
* :mod:`.axis` -- axis of rotation through the per-cycle centres (Tang et al. 2018, eq. 1);
* :mod:`.sagittal` -- the finger's sagittal plane from stylus landmarks;
* :mod:`.plausibility` -- physical plausibility: units, landmarks, quaternion convention;
* :mod:`.fit` -- the whole fit of a session into a :class:`~fingerfit.model.DigitModel`;
* :mod:`.joint` -- one joint between any two tracked segments (:func:`fit_joint`,
  :func:`hinge_axis`, :func:`two_axis`, :func:`joint_centre`; ``docs/joint.md``), with
  :mod:`.joint_checks`, :mod:`.joint_estimators`, :mod:`.bootstrap`, :mod:`.joint_result`.
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

_EXPORTS = {
    "FitError": ".fit",
    "FitOptions": ".fit",
    "fit_session": ".fit",
    "JointFit": ".joint",
    "JointQuality": ".joint",
    "fit_joint": ".joint",
    "hinge_axis": ".joint",
    "joint_centre": ".joint",
    "two_axis": ".joint",
    "SaddleFit": ".saddle",
    "fit_saddle": ".saddle",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
__all__ = [
    "FitError",
    "FitOptions",
    "JointFit",
    "JointQuality",
    "SaddleFit",
    "fit_joint",
    "fit_saddle",
    "fit_session",
    "hinge_axis",
    "joint_centre",
    "two_axis",
]

if TYPE_CHECKING:
    from .fit import FitError, FitOptions, fit_session
    from .joint import JointFit, JointQuality, fit_joint, hinge_axis, joint_centre, two_axis
    from .saddle import SaddleFit, fit_saddle
