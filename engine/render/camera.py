"""Scaled orthographic camera (thesis 2.1.2, 4.2) with a view azimuth about the vertical.

Projection of a world point X (metres) to pixel (u, v), u right and v down:

    (x_c, y_c, z_c) = R_cam_world(azimuth) @ X
    u = cx + scale * ( cos(theta_z) x_c - sin(theta_z) y_c )
    v = cy + scale * ( sin(theta_z) x_c + cos(theta_z) y_c )

At azimuth 0 the camera looks at the body's front (along -z): camera x = world x, camera y =
-world y (image down) and depth z_c = -z grows away from the camera, the convention of the
public benchmark cases (so (cx, cy) is the image of the world origin). A positive azimuth
moves the camera counter-clockwise seen from above, towards the body's left (+x) side; 90 deg
is a side view. theta_z rotates the image clockwise on screen (v points down).

Beyond the thesis, ``distance`` > 0 makes it a pinhole camera that far (metres) in front of
the world origin, with the same scale at the origin's depth d = 0:

    u = cx + scale * D / (D + d) * ( cos(theta_z) x_c - sin(theta_z) y_c ),   d = depth(X)

(and v likewise). A phone 3-4 m from a performer sees a part 0.5 m nearer 15 % larger; the
scaled orthographic model cannot (DESIGN.md, stage 1). ``distance`` 0 is the thesis' camera.
Capsule radii stay at the origin's scale (:mod:`engine.render.capsules`): their change with
depth is a fraction of a pixel where the ends' positions move several.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import TypedDict, Unpack

import numpy as np


class CameraChanges(TypedDict, total=False):
    """Fields :meth:`Camera.with_` may change, with their types."""

    scale: float
    theta_z: float
    cx: float
    cy: float
    azimuth: float
    width: int
    height: int
    distance: float


@dataclass(frozen=True)
class Camera:
    """Scaled orthographic camera.

    Attributes
    ----------
    scale : float
        Pixels per metre.
    theta_z : float
        In-plane rotation, radians.
    cx, cy : float
        Image position of the world origin, pixels.
    azimuth : float
        View direction about the vertical axis, radians (0 = facing the body's front).
    width, height : int
        Image size in pixels.
    distance : float
        Metres from the camera to the world origin along the view; 0 = scaled orthographic.
    """

    scale: float
    theta_z: float = 0.0
    cx: float = 0.0
    cy: float = 0.0
    azimuth: float = 0.0
    width: int = 320
    height: int = 240
    distance: float = 0.0

    # Cached: hot loops read these per call, and the camera is immutable. cached_property
    # writes the instance __dict__ directly, which a frozen dataclass allows.
    @cached_property
    def R_cam_world(self) -> np.ndarray:
        """Rotation from world to camera axes (x right, y down, z away), shape (3, 3)."""
        a = self.azimuth
        # camera sits at direction (sin a, 0, cos a) from the subject, looking back at it
        forward = -np.array([np.sin(a), 0.0, np.cos(a)])
        right = np.cross(forward, [0.0, 1.0, 0.0])
        down = np.cross(forward, right)
        return _frozen(np.stack([right, down, forward]))

    @cached_property
    def A(self) -> np.ndarray:
        """The 2x3 linear part of the projection: pixels per metre, shape (2, 3)."""
        c, s = np.cos(self.theta_z), np.sin(self.theta_z)
        return _frozen(self.scale * (np.array([[c, -s], [s, c]]) @ self.R_cam_world[:2]))

    @cached_property
    def view_dir(self) -> np.ndarray:
        """Unit world vector pointing from the camera into the scene (depth grows along it)."""
        return _frozen(self.R_cam_world[2].copy())

    def project(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) -> pixel positions (..., 2) as (u, v)."""
        p = np.asarray(points, dtype=float)
        uv = p @ self.A.T
        if self.distance > 0:
            # points nearer than a tenth of the distance are clamped there (never behind)
            d = np.maximum(self.distance + p @ self.view_dir, 0.1 * self.distance)
            uv = uv * (self.distance / d)[..., None]
        return uv + np.array([self.cx, self.cy])

    def depth(self, points: np.ndarray) -> np.ndarray:
        """Depth along the viewing direction (larger is farther), (..., 3) -> (...)."""
        return np.asarray(points, dtype=float) @ self.view_dir

    def with_(self, **changes: Unpack[CameraChanges]) -> Camera:
        """A copy with some fields changed."""
        return replace(self, **changes)

    def resized(self, width: int, height: int) -> Camera:
        """This camera re-expressed for the same image at ``width`` x ``height`` pixels
        (the working-resolution camera in the video file's own pixels).

        Pixel centres sit on integers at both resolutions, so u_new = (u + 0.5) / k - 0.5.
        """
        k = self.height / height
        if abs(k - 1.0) < 1e-12:
            return self
        return Camera(
            scale=self.scale / k, theta_z=self.theta_z, cx=(self.cx + 0.5) / k - 0.5,
            cy=(self.cy + 0.5) / k - 0.5, azimuth=self.azimuth, width=width, height=height,
            distance=self.distance,
        )  # fmt: skip

    def to_dict(self) -> dict:
        """The DESIGN.md ``camera`` block (degrees at the edge)."""
        return {
            "scale": float(self.scale),
            "theta_z_deg": float(np.degrees(self.theta_z)),
            "cx": float(self.cx),
            "cy": float(self.cy),
            "azimuth_deg": float(np.degrees(self.azimuth)),
            "width": int(self.width),
            "height": int(self.height),
            "perspective_distance_m": float(self.distance),
        }

    @classmethod
    def from_dict(cls, d: dict) -> Camera:
        return cls(
            scale=float(d["scale"]),
            theta_z=float(np.radians(d.get("theta_z_deg", 0.0))),
            cx=float(d.get("cx", 0.0)),
            cy=float(d.get("cy", 0.0)),
            azimuth=float(np.radians(d.get("azimuth_deg", 0.0))),
            width=int(d.get("width", 320)),
            height=int(d.get("height", 240)),
            distance=float(d.get("perspective_distance_m", 0.0)),
        )


def _frozen(a: np.ndarray) -> np.ndarray:
    """Read-only view: cached arrays are shared by every caller of one camera."""
    a.setflags(write=False)
    return a
