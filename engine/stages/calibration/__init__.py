"""Stage 1: calibrate the scaled orthographic camera from the first frame (thesis 4.2).

The thesis compares the principal axes (PCA of the pixel positions) of the input body region
at t' = 0 with those of the projected calibration posture B_0 (it assumes B'_0 = B_0): the
ratio of principal lengths gives the scale s, the angle between principal directions the
in-plane angle theta_z, and the centres the position (c_x, c_y).

Beyond the thesis, the view azimuth about the vertical is estimated by sampling: the
calibration posture is projected at each sampled azimuth, PCA-calibrated as above, rendered,
and the azimuth with the smallest d_S (eq. 4.4) against the input region is kept, so face-on
and down-the-line (side) videos both work. Front and back views (azimuth a and a + 180 deg)
give mirror-image silhouettes that differ only in the internal edges; both are sampled.

Optionally (``above_ankles``) the last refinement fits scale and position by d_A over the
rows above the ankles only (:func:`.search._refine_above_ankles`): planted shoes print into
a static-camera background model, and a whole-body fit then shrinks the scale to end the legs
where the region does.

    settings    CalibrationSettings
    initial     a first camera per azimuth: PCA (4.2) or from 2D keypoints
    search      the greedy polish: on one frame by d_S (+ d_K), above the ankles, on many frames
    views       calibrate: azimuths sampled and refined; mirror_azimuth
    body_width  fit_body_shape: the performer's capsule radii per part group
"""

from engine.stages.calibration.body_width import WIDTH_GROUPS, fit_body_shape
from engine.stages.calibration.initial import (
    PrincipalAxes,
    keypoint_camera,
    pca_camera,
    principal_axes,
)
from engine.stages.calibration.search import refine_on_frames
from engine.stages.calibration.settings import CalibrationSettings
from engine.stages.calibration.views import calibrate, mirror_azimuth

__all__ = [
    "WIDTH_GROUPS",
    "CalibrationSettings",
    "PrincipalAxes",
    "calibrate",
    "fit_body_shape",
    "keypoint_camera",
    "mirror_azimuth",
    "pca_camera",
    "principal_axes",
    "refine_on_frames",
]
