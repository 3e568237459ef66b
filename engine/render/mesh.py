"""Mesh renderer for the visual body (thesis 2.1.1 item 1, fig. 2.1 b; 4.3): pyrender, headless.

The body is drawn as the capsules of :mod:`engine.body.shapes`, smooth shaded, coloured per
part (skin on the head and forearms, a shirt, trousers, shoes and hair painted as vertex
colours so that the silhouette stays exactly that of the capsules). Keeping the visual mesh
equal to the capsule model means the analytic rasteriser (``render/capsules/``) and the
synthetic videos agree up to mesh tessellation.

The camera is pyrender's orthographic camera placed so that the pixel *centre* (u, v), with
integer u, v, shows the world point that :meth:`engine.render.camera.Camera.project` maps to
(u, v): OpenGL samples pixels at their centres, (i + 0.5) in window coordinates.
"""

from __future__ import annotations

import os

# The one place the engine writes an environment variable: PyOpenGL picks its platform when it
# is first imported, so headless EGL must be chosen before pyrender (and OpenGL) are imported.
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numpy as np  # noqa: E402
import pyrender  # noqa: E402
import trimesh  # noqa: E402

from engine.body.shapes import (  # noqa: E402
    CAPSULE_PART,
    N_CAPSULES,
    BodyShape,
    capsule_endpoints,
)
from engine.body.skeleton import PART_INDEX  # noqa: E402
from engine.errors import InvalidInput  # noqa: E402
from engine.render.camera import Camera  # noqa: E402

#: Default clothing colours, linear RGB in [0, 1].
DEFAULT_STYLE: dict[str, tuple[float, float, float]] = {
    "skin": (0.86, 0.67, 0.53),
    "hair": (0.18, 0.12, 0.08),
    "shirt": (0.16, 0.36, 0.72),
    "trousers": (0.22, 0.22, 0.26),
    "shoes": (0.07, 0.07, 0.08),
}

_SKIN_PARTS = {"head", "l_lower_arm", "r_lower_arm"}
_TROUSER_PARTS = {"l_upper_leg", "r_upper_leg", "l_lower_leg", "r_lower_leg"}
_SHOE_FROM_T = 0.86  # fraction of a shin capsule's axis below which it is a shoe


def _capsule_mesh(radius: float, length: float, sections: int) -> trimesh.Trimesh:
    """Capsule along +z from (0, 0, 0) to (0, 0, length), smooth normals."""
    mesh = trimesh.creation.capsule(
        height=max(length, 1e-6), radius=radius, count=[sections, sections]
    )
    mesh.apply_translation([0.0, 0.0, length / 2.0])
    return mesh


def _pose_from_segment(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """4x4 pose taking the local +z axis from the origin onto segment a -> b."""
    d = b - a
    n = np.linalg.norm(d)
    z = d / n if n > 1e-9 else np.array([0.0, 1.0, 0.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, a
    return T


def _part_colours(style: dict[str, tuple[float, float, float]]) -> np.ndarray:
    """Base colour of each capsule, shape (C, 3)."""
    names = {v: k for k, v in PART_INDEX.items()}
    out = np.empty((N_CAPSULES, 3))
    for c, p in enumerate(CAPSULE_PART):
        part = names[int(p)]
        if part in _SKIN_PARTS:
            out[c] = style["skin"]
        elif part in _TROUSER_PARTS:
            out[c] = style["trousers"]
        else:
            out[c] = style["shirt"]
    # the pelvis capsule (first abdomen capsule, between the hips) belongs to the trousers
    out[0] = style["trousers"]
    return out


def camera_pose(camera: Camera, depth_offset: float) -> np.ndarray:
    """World pose (4x4, camera to world) of the pyrender camera matching ``camera``.

    Parameters
    ----------
    camera : Camera
    depth_offset : float
        Position of the camera along the viewing direction, metres (it must lie in front of
        every point drawn; orthographic images do not depend on it otherwise).

    Returns
    -------
    T_world_cam : ndarray, shape (4, 4)
        pyrender convention: camera x right, y up, looking along its -z.
    """
    A = camera.A / camera.scale  # rows: world directions of image u and v, orthonormal
    x_cam, y_cam = A[0], -A[1]
    z_cam = np.cross(x_cam, y_cam)
    # centre the view so that pixel centre (W/2 - 0.5, H/2 - 0.5) shows the projection centre
    pos = (
        x_cam * (camera.width / 2.0 - 0.5 - camera.cx) / camera.scale
        - y_cam * (camera.height / 2.0 - 0.5 - camera.cy) / camera.scale
        + z_cam * (-depth_offset)
    )
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x_cam, y_cam, z_cam, pos
    return T


class MeshRenderer:
    """Reusable offscreen renderer of the capsule body (one OpenGL context per instance).

    Creating the context is costly (tens of ms), so keep one renderer per image size and
    call :meth:`close` when done (or use it as a context manager).

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    style : dict, optional
        Colours, keys of :data:`DEFAULT_STYLE`.
    sections : int
        Tessellation of each capsule (segments around and along the caps).
    """

    def __init__(
        self,
        width: int,
        height: int,
        *,
        style: dict[str, tuple[float, float, float]] | None = None,
        sections: int = 24,
    ) -> None:
        if int(width) < 2 or int(height) < 2:
            raise InvalidInput(f"width and height must be at least 2 px, got {width}x{height}")
        self.width, self.height = int(width), int(height)
        self.style = {**DEFAULT_STYLE, **(style or {})}
        self._colours = _part_colours(self.style)
        self._sections = int(sections)
        self._meshes: dict[tuple[int, int, int], pyrender.Mesh] = {}
        self._renderer: pyrender.OffscreenRenderer | None = pyrender.OffscreenRenderer(
            self.width, self.height
        )

    def __enter__(self) -> MeshRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Release the OpenGL context (idempotent)."""
        if self._renderer is not None:
            self._renderer.delete()
            self._renderer = None

    def _mesh(self, c: int, radius: float, length: float) -> pyrender.Mesh:
        # lengths are quantised to 0.1 mm so a rigid body reuses its meshes every frame
        key = (c, int(round(radius * 1e4)), int(round(length * 1e4)))
        mesh = self._meshes.get(key)
        if mesh is None:
            tm = _capsule_mesh(radius, length, self._sections)
            colours = np.tile(self._colours[c], (len(tm.vertices), 1))
            t = tm.vertices[:, 2] / max(length, 1e-6)
            if CAPSULE_PART[c] in (PART_INDEX["l_lower_leg"], PART_INDEX["r_lower_leg"]):
                colours[t > _SHOE_FROM_T] = self.style["shoes"]
            if CAPSULE_PART[c] == PART_INDEX["head"]:
                # hair on the crown and the back of the head (local -y is the body's back,
                # see render(): the head's local y axis is aimed at the body's front)
                z, y = tm.vertices[:, 2], tm.vertices[:, 1]
                hair = (z > length + 0.25 * radius) | ((y < -0.25 * radius) & (z > 0.2 * length))
                colours[hair] = self.style["hair"]
            material = pyrender.MetallicRoughnessMaterial(
                baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0, roughnessFactor=0.85
            )
            primitive = pyrender.Primitive(
                positions=tm.vertices,
                normals=tm.vertex_normals,
                indices=tm.faces,
                color_0=np.hstack([colours, np.ones((len(colours), 1))]),
                material=material,
            )
            mesh = pyrender.Mesh(primitives=[primitive])
            self._meshes[key] = mesh
        return mesh

    def render(
        self,
        joints: np.ndarray,
        shape: BodyShape,
        camera: Camera,
        *,
        background: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Render one posture.

        Parameters
        ----------
        joints : ndarray, shape (17, 3)
            World joint positions, metres.
        shape : BodyShape
            Capsule radii (and the body the joints belong to).
        camera : Camera
            Its width/height must equal the renderer's.
        background : ndarray of uint8, shape (H, W, 3), optional
            Image behind the body; uniform grey when omitted.

        Returns
        -------
        image : ndarray of uint8, shape (H, W, 3)
            RGB.
        mask : ndarray of bool, shape (H, W)
            Pixels covered by the body.

        Raises
        ------
        InvalidInput
            Wrong shapes, non-finite joints, or a camera of another image size.
        """
        if self._renderer is None:
            raise InvalidInput("renderer is closed")
        joints = self._check(joints, camera, background)
        H, W = self.height, self.width
        scene = pyrender.Scene(bg_color=[0.0, 0.0, 0.0, 0.0], ambient_light=[0.35, 0.35, 0.35])
        radii = np.asarray(shape.radii, dtype=float)
        self._add_body(scene, joints, radii)
        depths = camera.depth(joints)
        near = float(depths.min()) - 2.0 - float(radii.max())
        far_extent = float(depths.max() - near) + 2.0 + float(radii.max())
        cam = pyrender.OrthographicCamera(
            xmag=W / (2.0 * camera.scale),
            ymag=H / (2.0 * camera.scale),
            znear=0.05,
            zfar=far_extent + 1.0,
        )
        T_world_cam = camera_pose(camera, near)
        scene.add(cam, pose=T_world_cam)
        # key light from above the camera's shoulder, fill from the camera itself
        key = T_world_cam.copy()
        key[:3, :3] = key[:3, :3] @ _rx(-0.6) @ _ry(0.4)
        scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=2.0), pose=key)
        scene.add(pyrender.DirectionalLight(color=np.ones(3), intensity=0.8), pose=T_world_cam)

        colour, depth = self._renderer.render(scene)
        mask = depth > 0
        if background is None:
            background = np.full((H, W, 3), 128, dtype=np.uint8)
        image = np.where(mask[..., None], colour[..., :3], background).astype(np.uint8)
        return image, mask

    def _check(
        self, joints: np.ndarray, camera: Camera, background: np.ndarray | None
    ) -> np.ndarray:
        """The joints (17, 3) as floats, after refusing what :meth:`render` cannot draw."""
        joints = np.asarray(joints, dtype=float)
        if joints.shape != (17, 3) or not np.all(np.isfinite(joints)):
            raise InvalidInput(f"joints must be finite with shape (17, 3), got {joints.shape}")
        if (camera.width, camera.height) != (self.width, self.height):
            raise InvalidInput(
                f"camera is {camera.width}x{camera.height} but the renderer is "
                f"{self.width}x{self.height}"
            )
        shape = (self.height, self.width, 3)
        if background is not None and np.asarray(background).shape != shape:
            raise InvalidInput(
                f"background must have shape {shape}, got {np.asarray(background).shape}"
            )
        return joints

    def _add_body(self, scene: pyrender.Scene, joints: np.ndarray, radii: np.ndarray) -> None:
        """One capsule mesh per body part; the head's turned to face the body's front."""
        ends = capsule_endpoints(joints)  # (C, 2, 3)
        # the body's facing (for the back of the head): horizontal normal of the hip line
        across = joints[1] - joints[4]
        front = np.cross(across, [0.0, 1.0, 0.0])
        for c in range(N_CAPSULES):
            a, b = ends[c]
            pose = _pose_from_segment(a, b)
            if CAPSULE_PART[c] == PART_INDEX["head"] and np.linalg.norm(front) > 1e-9:
                z = pose[:3, 2]
                y = front - z * (front @ z)
                if np.linalg.norm(y) > 1e-6:
                    y /= np.linalg.norm(y)
                    pose[:3, 1], pose[:3, 0] = y, np.cross(y, z)
            scene.add(self._mesh(c, float(radii[c]), float(np.linalg.norm(b - a))), pose=pose)


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def textured_background(
    height: int, width: int, rng: np.random.Generator, *, horizon: float | None = None
) -> np.ndarray:
    """A plausible static scene: a textured wall above a floor.

    Parameters
    ----------
    height, width : int
        Image size.
    rng : numpy.random.Generator
        Source of every random choice (colours, texture, horizon).
    horizon : float, optional
        Image row of the wall/floor edge; random in the lower half when omitted.

    Returns
    -------
    image : ndarray of uint8, shape (H, W, 3)
    """
    H, W = int(height), int(width)
    if H < 2 or W < 2:
        raise InvalidInput(f"height and width must be at least 2, got {H}x{W}")
    if horizon is None:
        horizon = H * rng.uniform(0.6, 0.85)
    rows = np.arange(H)[:, None]
    cols = np.arange(W)[None, :]
    wall = rng.uniform(0.45, 0.85, 3)
    floor = rng.uniform(0.2, 0.55, 3)
    img = np.where((rows < horizon)[..., None], wall, floor) * np.ones((H, W, 1))
    # low-frequency blotches: a coarse random grid upsampled bilinearly
    img *= 1.0 + 0.12 * _smooth_noise(H, W, rng, cells=6)[..., None]
    # fine grain
    img *= 1.0 + 0.03 * rng.standard_normal((H, W))[..., None]
    # wall panels and floor boards give the edge detector something static to see
    period = rng.uniform(0.12, 0.3) * W
    phase = rng.uniform(0, period)
    seams = (np.abs(((cols + phase) % period) - period / 2) > period / 2 - 1) & (rows < horizon)
    img[np.broadcast_to(seams, (H, W))] *= 0.85
    depth = np.maximum(rows - horizon, 0) + 1.0
    boards = ((np.log(depth) * 6.0) % 1.0 < 0.08) & (rows > horizon + 1)
    img[np.broadcast_to(boards, (H, W))] *= 0.8
    edge = np.abs(rows - horizon) < 1.0
    img[np.broadcast_to(edge, (H, W))] *= 0.6
    return (np.clip(img, 0.0, 1.0) * 255.0).astype(np.uint8)


def _smooth_noise(H: int, W: int, rng: np.random.Generator, cells: int) -> np.ndarray:
    """Bilinearly upsampled uniform noise in [-1, 1], shape (H, W)."""
    g = rng.uniform(-1.0, 1.0, (cells + 1, cells + 1))
    y = np.linspace(0, cells, H)
    x = np.linspace(0, cells, W)
    y0 = np.minimum(y.astype(int), cells - 1)
    x0 = np.minimum(x.astype(int), cells - 1)
    fy, fx = (y - y0)[:, None], (x - x0)[None, :]
    g00, g01 = g[y0][:, x0], g[y0][:, x0 + 1]
    g10, g11 = g[y0 + 1][:, x0], g[y0 + 1][:, x0 + 1]
    return (g00 * (1 - fx) + g01 * fx) * (1 - fy) + (g10 * (1 - fx) + g11 * fx) * fy
