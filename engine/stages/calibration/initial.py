"""A first camera at one view azimuth: the thesis' PCA calibration (4.2 steps 1-7) from the
region's principal axes, or a closed-form fit to 2D keypoints (beyond the thesis).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.render import capsules
from engine.render.camera import Camera
from engine.stages.perception import MIRROR


@dataclass(frozen=True)
class PrincipalAxes:
    """Principal axes of a pixel region (thesis 4.2 steps 3-4).

    Attributes
    ----------
    centre : ndarray, shape (2,)
        Mean (u, v) pixel position.
    direction : ndarray, shape (2,)
        First eigenvector (u, v), unit, oriented with v decreasing (pointing "up" the body).
    length : float
        Extent of the region along ``direction``, pixels.
    """

    centre: np.ndarray
    direction: np.ndarray
    length: float

    @property
    def angle(self) -> float:
        """Angle of ``direction`` in the image, radians (atan2(v, u))."""
        return float(np.arctan2(self.direction[1], self.direction[0]))


def principal_axes(mask: np.ndarray) -> PrincipalAxes:
    """PCA of the pixel positions of a region (thesis 4.2 step 3).

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)

    Returns
    -------
    PrincipalAxes

    Raises
    ------
    InvalidInput
        If the mask has fewer than 3 pixels.
    """
    rows, cols = np.nonzero(mask)
    if rows.size < 3:
        raise InvalidInput(f"mask must contain a body region, got {rows.size} pixel(s)")
    uv = np.stack([cols, rows], axis=1).astype(float)
    centre = uv.mean(0)
    cov = np.cov((uv - centre).T)
    w, v = np.linalg.eigh(cov)
    d = v[:, np.argmax(w)]
    if d[1] > 0:
        d = -d
    proj = (uv - centre) @ d
    return PrincipalAxes(centre, d, float(proj.max() - proj.min() + 1.0))


def _wrap_half_turn(a: float) -> float:
    """Wrap an axis angle to (-pi/2, pi/2] (a principal axis has no sign)."""
    return float((a + np.pi / 2) % np.pi - np.pi / 2)


def pca_camera(
    joints: np.ndarray, shape: BodyShape, target: np.ndarray, *, azimuth: float = 0.0
) -> Camera:
    """Camera by the thesis' PCA calibration at one azimuth (4.2 steps 1-7).

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
        Calibration posture, world frame.
    shape : BodyShape
    target : ndarray of bool, shape (H, W)
        Input body region of the calibration frame.
    azimuth : float
        View azimuth, radians.

    Returns
    -------
    Camera
    """
    h, w = target.shape
    tgt = principal_axes(target)
    # default camera: a scale that fits the body comfortably, world origin mid-image
    height_m = max(float(np.ptp(joints[:, 1])), 0.3)
    s0 = 0.6 * h / height_m
    mid = joints.mean(0)
    cam0 = Camera(scale=s0, theta_z=0.0, cx=0.0, cy=0.0, azimuth=azimuth, width=w, height=h)
    off = np.array([w / 2, h / 2]) - cam0.project(mid)
    cam0 = cam0.with_(cx=float(off[0]), cy=float(off[1]))
    proj = principal_axes(capsules.silhouettes(joints[None], shape, cam0)[0])
    s = s0 * tgt.length / proj.length
    theta = _wrap_half_turn(tgt.angle - proj.angle)
    # centroid of the projection relative to the world origin, in metres of image plane
    q = (proj.centre - np.array([cam0.cx, cam0.cy])) / s0
    c, si = np.cos(theta), np.sin(theta)
    c_xy = tgt.centre - s * (np.array([[c, -si], [si, c]]) @ q)
    return Camera(
        scale=float(s), theta_z=theta, cx=float(c_xy[0]), cy=float(c_xy[1]),
        azimuth=azimuth, width=w, height=h,
    )  # fmt: skip


def keypoint_camera(
    joints: np.ndarray,
    keypoints: np.ndarray,
    confidence: np.ndarray,
    *,
    azimuth: float,
    width: int,
    height: int,
) -> Camera:
    """Camera at one azimuth that best puts the posture's joints on 2D keypoints.

    The weighted least-squares similarity (scale, in-plane angle, translation) from the
    posture's orthographic view at ``azimuth`` to the keypoints, in closed form (Umeyama
    1991), on the labels as given and on their mirror (a pose model swaps left and right);
    the better fit wins. Beyond the thesis' PCA (4.2), which only sees the region's axes.

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
    keypoints : ndarray, shape (17, 2)
        NaN where there is none.
    confidence : ndarray, shape (17,)
    azimuth : float
        Radians.
    width, height : int

    Raises
    ------
    InvalidInput
        Fewer than three keypoints carry weight.
    """
    ok = np.isfinite(keypoints).all(-1) & (confidence > 0)
    if ok.sum() < 3:
        raise InvalidInput("at least three 2D keypoints are needed to place the camera")
    base = Camera(scale=1.0, azimuth=azimuth, width=width, height=height)
    p = base.project(joints)
    fits = []
    for idx in (np.arange(len(joints)), MIRROR):
        k, w = np.nan_to_num(keypoints[idx]), np.where(ok[idx], confidence[idx], 0.0)
        pm, km = (w[:, None] * p).sum(0) / w.sum(), (w[:, None] * k).sum(0) / w.sum()
        a, b = p - pm, k - km
        h00 = (w * a[:, 0] * b[:, 0]).sum() + (w * a[:, 1] * b[:, 1]).sum()
        h01 = (w * a[:, 0] * b[:, 1]).sum() - (w * a[:, 1] * b[:, 0]).sum()
        theta = float(np.arctan2(h01, h00))
        scale = float(np.hypot(h00, h01) / max((w * (a**2).sum(1)).sum(), 1e-12))
        c, si = np.cos(theta), np.sin(theta)
        t = km - scale * (np.array([[c, -si], [si, c]]) @ pm)
        r = scale * (a @ np.array([[c, si], [-si, c]])) - b
        fits.append(((w * (r**2).sum(1)).sum(), scale, theta, t))
    _, scale, theta, t = min(fits, key=lambda f: f[0])
    return Camera(scale=max(scale, 1e-6), theta_z=theta, cx=float(t[0]), cy=float(t[1]),
                  azimuth=azimuth, width=width, height=height)  # fmt: skip
