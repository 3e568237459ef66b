"""Fast analytic rasteriser of the capsule body and the image measures d_A, d_E, d_S on it.

Thesis 4.3 renders the posed mesh with OpenGL and 4.4.1 compares the rendered region with the
input region (d_A eq. 4.1, d_E eq. 4.2-4.3, d_S eq. 4.4). The body here is a union of capsules
(:mod:`engine.body.shapes`), whose scaled orthographic projection is *exactly* a 2D capsule:
the points within ``radius_m * camera.scale`` pixels of the projected axis segment. So
coverage is computed analytically, row by row, with no mesh and no OpenGL; the silhouette
overlap of a posture needs O(rows x capsules) work and never an image.

What the rendered region contains
---------------------------------
silhouette
    pixels (u, v) (centres at integers; row = v, col = u) within the radius of any capsule.
labels
    the part of the nearest capsule surface at the pixel (see depth in :mod:`._raster`).
edges
    the *visible outline of every part*: pixels where part k is the nearest surface and that
    have a 4-neighbour not covered by part k. This is the silhouette boundary plus the
    internal boundaries where a nearer part overlaps a farther one (an arm in front of the
    torso), and no edges inside a part (its capsules are merged first). Seams at joints are
    removed by one local rule: a capsule running along a bone does not contribute the round
    cap at an end that sits on a joint shared with another part (``SEAM_END``), since that
    cap lies inside the neighbouring part. Consequence (an approximation of a real image's
    edges, not of the render): on the outside of a strongly bent joint the short arc of that
    cap that sticks out is not an edge. Because every part's outline depends only on its own
    capsules and the depth order, the incremental :class:`PartScorer` is exact.

Thesis 4.6.2: in belief propagation one part moves while the others keep their poses from the
previous iteration, so :class:`PartScorer` caches the others' rendering and scores many poses
of the moving part touching only that part's bounding box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.shapes import (
    CAPSULE_A,
    CAPSULE_B,
    CAPSULE_PART,
    CAPSULE_T,
    N_CAPSULES,
    BodyShape,
)
from engine.body.skeleton import BONE_CHILD, BONE_PARENT, N_PARTS, PART_BONES
from engine.errors import InvalidInput
from engine.measures import LAMBDA_A, LAMBDA_E, SIGMA_PX, XI, edge_cost_map
from engine.render import _raster
from engine.render.camera import Camera


def _seam_ends() -> np.ndarray:
    """Which capsule ends are seams with another part, shape (C, 2) bool (see module doc)."""
    bones = {(int(p), int(c)) for p, c in zip(BONE_PARENT, BONE_CHILD, strict=True)}
    part_joints = [
        {int(BONE_PARENT[b]) for b in PART_BONES[k]} | {int(BONE_CHILD[b]) for b in PART_BONES[k]}
        for k in range(N_PARTS)
    ]
    seam = np.zeros((N_CAPSULES, 2), dtype=bool)
    for c in range(N_CAPSULES):
        a, b, k = int(CAPSULE_A[c]), int(CAPSULE_B[c]), int(CAPSULE_PART[c])
        if (a, b) not in bones:
            continue  # pelvis and shoulder capsules: their caps are the body's outer shape
        for e, joint in ((0, a), (1, b)):
            t = CAPSULE_T[c, e]
            at_joint = (t == 0.0 and joint == a) or (t == 1.0 and joint == b)
            shared = any(joint in part_joints[j] for j in range(N_PARTS) if j != k)
            seam[c, e] = at_joint and shared
    seam.setflags(write=False)
    return seam


#: Capsule ends whose round cap is a seam inside a neighbouring part, shape (C, 2).
SEAM_END = _seam_ends()
#: Capsules of each part.
PART_CAPSULES: tuple[np.ndarray, ...] = tuple(
    np.flatnonzero(CAPSULE_PART == k).astype(np.int64) for k in range(N_PARTS)
)
_PART_I64 = np.ascontiguousarray(CAPSULE_PART, dtype=np.int64)
_ALL_CAPS = np.arange(N_CAPSULES, dtype=np.int64)


# ----------------------------------------------------------------------------- validation


def _check_joints(joints: np.ndarray, name: str, batch: bool) -> np.ndarray:
    j = np.asarray(joints, dtype=float)
    want = "(N, 17, 3)" if batch else "(17, 3)"
    if j.ndim != (3 if batch else 2) or j.shape[-2:] != (17, 3):
        raise InvalidInput(f"{name} must have shape {want}, got {j.shape}")
    if not np.all(np.isfinite(j)):
        raise InvalidInput(f"{name} contains NaN or infinite values")
    return j


def _check_part(part: int) -> int:
    if not isinstance(part, int | np.integer) or not 0 <= int(part) < N_PARTS:
        raise InvalidInput(f"part must be an int in 0..{N_PARTS - 1}, got {part!r}")
    return int(part)


def _check_camera_target(camera: Camera, target: Target) -> None:
    if target.silhouette.shape != (camera.height, camera.width):
        raise InvalidInput(
            f"target is {target.silhouette.shape} (H, W) but the camera renders "
            f"({camera.height}, {camera.width})"
        )


# ----------------------------------------------------------------------------- projection


@dataclass(frozen=True)
class ProjectedCapsules:
    """Capsules of postures in the image.

    Attributes
    ----------
    ends_px : ndarray, shape (..., C, 2, 2)
        Axis ends (capsule, end, (u, v)), pixels.
    radius_px : ndarray, shape (C,)
        Radii in pixels (``radius_m * camera.scale``).
    depth : ndarray, shape (..., C, 2)
        Depth of the axis ends along the viewing direction, metres (larger is farther).
    radius_m : ndarray, shape (C,)
        Radii in metres (for surface depth).
    scale : float
        Pixels per metre.
    """

    ends_px: np.ndarray
    radius_px: np.ndarray
    depth: np.ndarray
    radius_m: np.ndarray
    scale: float


def project_capsules(joints: np.ndarray, shape: BodyShape, camera: Camera) -> ProjectedCapsules:
    """Project the capsule body of postures (thesis 4.3 with capsules instead of a mesh).

    Parameters
    ----------
    joints : ndarray, shape (..., 17, 3)
        World joint positions, metres.
    shape : BodyShape
    camera : Camera

    Returns
    -------
    ProjectedCapsules

    Raises
    ------
    InvalidInput
        If ``joints`` is not (..., 17, 3) or not finite.
    """
    j = np.asarray(joints, dtype=float)
    if j.ndim < 2 or j.shape[-2:] != (17, 3):
        raise InvalidInput(f"joints must have shape (..., 17, 3), got {j.shape}")
    if not np.all(np.isfinite(j)):
        raise InvalidInput("joints contains NaN or infinite values")
    return _project(j, shape, camera)


def _project(j: np.ndarray, shape: BodyShape, camera: Camera) -> ProjectedCapsules:
    a = j[..., CAPSULE_A, :]
    b = j[..., CAPSULE_B, :]
    ends = a[..., None, :] + CAPSULE_T[..., None] * (b - a)[..., None, :]  # (..., C, 2, 3)
    radius_m = np.asarray(shape.radii, dtype=float)
    return ProjectedCapsules(
        ends_px=np.ascontiguousarray(camera.project(ends)),
        radius_px=radius_m * float(camera.scale),
        depth=np.ascontiguousarray(camera.depth(ends)),
        radius_m=radius_m,
        scale=float(camera.scale),
    )


# ----------------------------------------------------------------------------- full render


@dataclass(frozen=True)
class Render:
    """A rendered capsule body over an image box.

    Attributes
    ----------
    silhouette : ndarray of bool, shape (H, W)
    labels : ndarray of int8, shape (H, W)
        Visible part index 0..11, -1 for background.
    edges : ndarray of bool, shape (H, W)
        Visible part outlines (see the module docstring).
    depth : ndarray of float64, shape (H, W)
        Depth of the visible surface, metres; inf on the background.
    box : tuple of int
        (row0, row1, col0, col1), half-open, of the image window rendered.
    """

    silhouette: np.ndarray
    labels: np.ndarray
    edges: np.ndarray
    depth: np.ndarray
    box: tuple[int, int, int, int]


def _raster_box(
    pc: ProjectedCapsules, caps: np.ndarray, box: tuple[int, int, int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    r0, r1, c0, c1 = box
    z = np.full((r1 - r0, c1 - c0), np.inf)
    label = np.full(z.shape, -1, dtype=np.int8)
    cov = np.zeros(z.shape, dtype=np.uint16)
    body = np.zeros(z.shape, dtype=np.uint16)
    _raster.raster_parts(
        pc.ends_px, pc.depth, pc.radius_px, pc.radius_m, _PART_I64, SEAM_END, caps,
        pc.scale, r0, c0, z, label, cov, body,
    )  # fmt: skip
    return z, label, cov, body


def _render_caps(
    pc: ProjectedCapsules, caps: np.ndarray, camera: Camera, box: tuple[int, int, int, int]
) -> Render:
    r0, r1, c0, c1 = box
    # one pixel more on each side (inside the image) so outlines at the box border are right
    g = (max(r0 - 1, 0), min(r1 + 1, camera.height), max(c0 - 1, 0), min(c1 + 1, camera.width))
    z, label, cov, body = _raster_box(pc, caps, g)
    edges = np.empty(z.shape, dtype=bool)
    _raster.edge_mask(label, cov, body, edges)
    crop = np.s_[r0 - g[0] : r1 - g[0], c0 - g[2] : c1 - g[2]]
    return Render(
        silhouette=label[crop] >= 0,
        labels=label[crop].copy(),
        edges=edges[crop].copy(),
        depth=z[crop].copy(),
        box=box,
    )


def _check_box(box: tuple[int, int, int, int] | None, camera: Camera) -> tuple[int, int, int, int]:
    if box is None:
        return (0, camera.height, 0, camera.width)
    try:
        r0, r1, c0, c1 = (int(x) for x in box)
    except (TypeError, ValueError) as exc:
        raise InvalidInput(f"box must be (row0, row1, col0, col1), got {box!r}") from exc
    if not (0 <= r0 <= r1 <= camera.height and 0 <= c0 <= c1 <= camera.width):
        raise InvalidInput(f"box {box!r} must lie inside the {camera.height}x{camera.width} image")
    return (r0, r1, c0, c1)


def render(
    joints: np.ndarray,
    shape: BodyShape,
    camera: Camera,
    *,
    box: tuple[int, int, int, int] | None = None,
) -> Render:
    """Render one posture's capsule body: silhouette, part labels, edges (thesis 4.3).

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
    shape : BodyShape
    camera : Camera
        Image size is ``(camera.height, camera.width)``.
    box : (row0, row1, col0, col1), optional
        Half-open image window to render; the whole image by default. The result is the
        crop of the whole-image render (edges at the window border included correctly).

    Returns
    -------
    Render

    Raises
    ------
    InvalidInput
        Bad ``joints`` shape or values, or ``box`` outside the image.
    """
    j = _check_joints(joints, "joints", batch=False)
    b = _check_box(box, camera)
    return _render_caps(_project(j, shape, camera), _ALL_CAPS, camera, b)


def silhouettes(joints: np.ndarray, shape: BodyShape, camera: Camera) -> np.ndarray:
    """Silhouettes of many postures, shape (N, H, W) bool.

    Raises
    ------
    InvalidInput
        If ``joints`` is not (N, 17, 3) or not finite.
    """
    j = _check_joints(joints, "joints", batch=True)
    pc = _project(j, shape, camera)
    out = np.zeros((j.shape[0], camera.height, camera.width), dtype=bool)
    _raster.fill_silhouettes(pc.ends_px, pc.radius_px, out)
    return out


# ----------------------------------------------------------------------------- target


@dataclass(frozen=True)
class Target:
    """The input body region S' prepared for fast comparison (thesis 4.4.1).

    Attributes
    ----------
    silhouette : ndarray of bool, shape (H, W)
        Input silhouette A'.
    edges : ndarray of bool, shape (H, W)
        Input edges E'.
    cost : ndarray of float64, shape (H, W)
        min(D^2 / sigma^2, xi), D = distance to the nearest pixel of E' (eq. 4.3).
    prefix : ndarray of int32, shape (H, W + 1)
        Row prefix sums of ``silhouette`` (overlap of a column span in O(1)).
    area : int
        |A'|.
    sigma_px, xi : float
        Parameters of eq. 4.3.
    """

    silhouette: np.ndarray
    edges: np.ndarray
    cost: np.ndarray
    prefix: np.ndarray
    area: int
    sigma_px: float
    xi: float

    @classmethod
    def from_masks(
        cls,
        silhouette: np.ndarray,
        edges: np.ndarray,
        *,
        sigma_px: float = SIGMA_PX,
        xi: float = XI,
    ) -> Target:
        """Precompute the truncated squared edge distance map and the silhouette sums.

        Parameters
        ----------
        silhouette, edges : ndarray of bool, shape (H, W)
        sigma_px : float
            sigma of eq. 4.3, pixels (default :data:`engine.measures.SIGMA_PX`).
        xi : float
            Truncation xi of eq. 4.3 (default :data:`engine.measures.XI`).

        Raises
        ------
        InvalidInput
            Masks not 2D, of different shapes, or non-positive ``sigma_px`` / ``xi``.
        """
        sil = np.asarray(silhouette)
        edg = np.asarray(edges)
        if sil.ndim != 2 or sil.shape[0] < 1 or sil.shape[1] < 1:
            raise InvalidInput(f"silhouette must be a 2D (H, W) mask, got shape {sil.shape}")
        if edg.shape != sil.shape:
            raise InvalidInput(
                f"edges must have the silhouette's shape {sil.shape}, got {edg.shape}"
            )
        sil = np.ascontiguousarray(sil.astype(bool))
        edg = np.ascontiguousarray(edg.astype(bool))
        cost = edge_cost_map(edg, sigma_px=sigma_px, xi=xi)
        prefix = np.zeros((sil.shape[0], sil.shape[1] + 1), dtype=np.int32)
        np.cumsum(sil, axis=1, out=prefix[:, 1:])
        return cls(sil, edg, cost, prefix, int(np.count_nonzero(sil)), float(sigma_px), float(xi))

    @classmethod
    def from_render(cls, r: Render, **kwargs: float) -> Target:
        """A target from a rendered body (identity tests, synthetic cases)."""
        return cls.from_masks(r.silhouette, r.edges, **kwargs)


def _d_A(area: np.ndarray, inter: np.ndarray, target_area: int) -> np.ndarray:
    total = area + target_area
    return np.where(total > 0, 1.0 - 2.0 * inter / np.maximum(total, 1), 0.0)


def _d_E(sum_cost: np.ndarray, count: np.ndarray, xi: float) -> np.ndarray:
    # normalised by the number of rendered edge pixels so postures with long and short
    # outlines are comparable; no rendered edge at all scores the worst value xi
    return np.where(count > 0, sum_cost / np.maximum(count, 1), xi)


def _project_batch(
    joints: np.ndarray, target: Target, shape: BodyShape, camera: Camera
) -> ProjectedCapsules:
    """Checked ``joints`` (N, 17, 3) and ``target`` of a batch measure, projected."""
    j = _check_joints(joints, "joints", batch=True)
    _check_camera_target(camera, target)
    return _project(j, shape, camera)


def d_A_batch(
    joints: np.ndarray,
    target: Target,
    shape: BodyShape,
    camera: Camera,
    *,
    subpixel_rows: int = 0,
) -> np.ndarray:
    """Silhouette difference d_A (thesis eq. 4.1) of many postures, no image allocated.

    By default a pixel is in the body when its centre is (as in :func:`render`). With
    ``subpixel_rows`` > 0 (beyond the thesis) the body's area is measured continuously: that
    many sub-rows per pixel row with exact column spans, the target's pixels as unit boxes,
    so d_A changes smoothly when a part moves by a fraction of a pixel instead of only when
    a pixel centre is crossed. Measured to change little in stage 3
    (``CandidateSettings.subpixel_rows``).

    Parameters
    ----------
    joints : ndarray, shape (N, 17, 3)
    target : Target
    shape : BodyShape
    camera : Camera
    subpixel_rows : int
        0 (pixel centres) or the sub-rows per pixel row.

    Returns
    -------
    d : ndarray, shape (N,)

    Raises
    ------
    InvalidInput
        Bad ``joints`` or ``subpixel_rows``, or a target whose size differs from the camera's
        image.
    """
    if not isinstance(subpixel_rows, int | np.integer) or subpixel_rows < 0:
        raise InvalidInput(f"subpixel_rows must be an integer >= 0, got {subpixel_rows!r}")
    pc = _project_batch(joints, target, shape, camera)
    if subpixel_rows:
        smooth = np.empty((pc.ends_px.shape[0], 2))
        _raster.sil_counts_smooth(
            pc.ends_px, pc.radius_px, target.prefix, int(subpixel_rows), smooth
        )
        return _d_A(smooth[:, 0], smooth[:, 1], target.area)
    out = np.empty((pc.ends_px.shape[0], 2), dtype=np.int64)
    _raster.sil_counts(pc.ends_px, pc.radius_px, target.prefix, out)
    return _d_A(out[:, 0], out[:, 1], target.area)


def d_S_batch(
    joints: np.ndarray,
    target: Target,
    shape: BodyShape,
    camera: Camera,
    *,
    lambda_A: float = LAMBDA_A,
    lambda_E: float = LAMBDA_E,
) -> np.ndarray:
    """Region difference d_S = lambda_A d_A + lambda_E d_E of many postures (thesis eq. 4.4).

    d_A is eq. 4.1; d_E is eq. 4.2-4.3 divided by the number of rendered edge pixels (a mean
    truncated chamfer distance in [0, xi], comparable across postures). Each posture is
    rasterised only inside its own bounding box.

    Parameters
    ----------
    joints : ndarray, shape (N, 17, 3)
    target : Target
    shape : BodyShape
    camera : Camera
    lambda_A, lambda_E : float
        Weights of eq. 4.4 (defaults in :mod:`engine.measures`).

    Returns
    -------
    d : ndarray, shape (N,)

    Raises
    ------
    InvalidInput
        Bad ``joints``, or a target whose size differs from the camera's image.
    """
    pc = _project_batch(joints, target, shape, camera)
    n = pc.ends_px.shape[0]
    out_i = np.empty((n, 3), dtype=np.int64)
    out_f = np.empty(n)
    _raster.full_counts(
        pc.ends_px, pc.depth, pc.radius_px, pc.radius_m, _PART_I64, SEAM_END, pc.scale,
        target.silhouette, target.cost, out_i, out_f,
    )  # fmt: skip
    dA = _d_A(out_i[:, 0], out_i[:, 1], target.area)
    dE = _d_E(out_f, out_i[:, 2], target.xi)
    return lambda_A * dA + lambda_E * dE


# ----------------------------------------------------------------------------- incremental


@dataclass
class _Fixed:
    """The rendering of every part but one, over the whole image."""

    z: np.ndarray
    sil: np.ndarray
    edge: np.ndarray
    flags: np.ndarray
    area: int
    inter: int
    n_edge: int
    sum_edge: float


class PartScorer:
    """d_S of a body where one part moves and the others stay (thesis 4.6.2, eq. 4.16).

    The rendering of all parts but the moving one is cached (per moving part, built on first
    use); ``score`` then rasterises only the moving part's capsules inside their bounding
    box and combines counts:

    - d_A: |A| = |fixed| + |moving \\ fixed|, |A and A'| likewise (exact);
    - d_E: fixed outline pixels hidden by a nearer moving surface are removed, the moving
      part's visible outline pixels are added (exact, since every part's outline depends
      only on its own capsules and the depth order; equal to a full render up to exact depth
      ties, which the full render breaks by capsule order).

    The configuration is a set of part poses, not necessarily one connected skeleton: each
    part's capsules come from the ``joints`` array they were last set from.

    Parameters
    ----------
    target : Target
    shape : BodyShape
    camera : Camera
    joints : ndarray, shape (17, 3)
        Initial pose of every part.
    lambda_A, lambda_E : float
        Weights of eq. 4.4.

    Raises
    ------
    InvalidInput
        Bad ``joints``, or a target whose size differs from the camera's image.
    """

    def __init__(
        self,
        target: Target,
        shape: BodyShape,
        camera: Camera,
        joints: np.ndarray,
        *,
        lambda_A: float = LAMBDA_A,
        lambda_E: float = LAMBDA_E,
    ) -> None:
        _check_camera_target(camera, target)
        self.target = target
        self.shape = shape
        self.camera = camera
        self.lambda_A = float(lambda_A)
        self.lambda_E = float(lambda_E)
        self._fixed: dict[int, _Fixed] = {}
        # the camera is fixed: its projection and radii are computed once, not per call
        self._rad_m = np.asarray(shape.radii, dtype=float)
        self._rad_px = self._rad_m * float(camera.scale)
        self._A_T = camera.A.T
        self._c = np.array([camera.cx, camera.cy])
        self._view = camera.view_dir
        self.set_pose(joints)

    def set_pose(self, joints: np.ndarray) -> None:
        """Set every part's pose from one posture (17, 3)."""
        j = _check_joints(joints, "joints", batch=False)
        pc = _project(j, self.shape, self.camera)
        self._ends = pc.ends_px.copy()
        self._depth = pc.depth.copy()
        self._fixed.clear()

    def update_part(self, part: int, joints: np.ndarray) -> None:
        """Move one part to its pose in ``joints`` (17, 3); the other parts stay."""
        p = _check_part(part)
        j = _check_joints(joints, "joints", batch=False)
        caps = PART_CAPSULES[p]
        pc = _project(j[None], self.shape, self.camera)
        self._ends[caps] = pc.ends_px[0, caps]
        self._depth[caps] = pc.depth[0, caps]
        self._fixed = {k: v for k, v in self._fixed.items() if k == p}

    def _current(self) -> ProjectedCapsules:
        rm = np.asarray(self.shape.radii, dtype=float)
        s = float(self.camera.scale)
        return ProjectedCapsules(self._ends, rm * s, self._depth, rm, s)

    def _fixed_for(self, part: int) -> _Fixed:
        f = self._fixed.get(part)
        if f is None:
            caps = np.setdiff1d(_ALL_CAPS, PART_CAPSULES[part])
            t = self.target
            # the whole-image render of the other parts, touching only the rows they cover
            z = np.empty(t.silhouette.shape)
            sil = np.zeros(t.silhouette.shape, dtype=bool)
            edge = np.zeros(t.silhouette.shape, dtype=bool)
            flags = np.zeros(t.silhouette.shape, dtype=np.uint8)
            counts = np.empty(3, dtype=np.int64)
            _raster.render_image(
                self._ends, self._depth, self._rad_px, self._rad_m, _PART_I64, SEAM_END, caps,
                float(self.camera.scale), t.silhouette, z, sil, edge, flags, counts,
            )  # fmt: skip
            f = _Fixed(
                z=z,
                sil=sil,
                edge=edge,
                flags=flags,
                area=int(counts[0]),
                inter=int(counts[1]),
                n_edge=int(counts[2]),
                sum_edge=float(t.cost[edge].sum()),
            )
            self._fixed[part] = f
        return f

    def render(self) -> Render:
        """Full render of the current configuration."""
        return _render_caps(self._current(), _ALL_CAPS, self.camera, _check_box(None, self.camera))

    def current_score(self) -> float:
        """d_S of the current configuration."""
        r = self.render()
        t = self.target
        area = np.count_nonzero(r.silhouette)
        inter = np.count_nonzero(r.silhouette & t.silhouette)
        dA = _d_A(np.array(area), np.array(inter), t.area)
        dE = _d_E(np.array(t.cost[r.edges].sum()), np.array(np.count_nonzero(r.edges)), t.xi)
        return float(self.lambda_A * dA + self.lambda_E * dE)

    def score(self, part: int, joints_samples: np.ndarray) -> np.ndarray:
        """d_S with ``part`` at each sampled pose and the other parts fixed.

        Parameters
        ----------
        part : int
            Moving part, 0..11.
        joints_samples : ndarray, shape (S, 17, 3)
            Only the joints that place ``part``'s capsules are read.

        Returns
        -------
        d : ndarray, shape (S,)

        Raises
        ------
        InvalidInput
            Bad ``part`` or ``joints_samples``.
        """
        p = _check_part(part)
        j = _check_joints(joints_samples, "joints_samples", batch=True)
        caps = PART_CAPSULES[p]
        fx = self._fixed_for(p)
        S = j.shape[0]
        # project only the moving part's capsules; other rows are never read by the kernel
        a = j[:, CAPSULE_A[caps], :]
        b = j[:, CAPSULE_B[caps], :]
        e3 = a[:, :, None, :] + CAPSULE_T[caps][None, :, :, None] * (b - a)[:, :, None, :]
        ends = np.zeros((S, N_CAPSULES, 2, 2))
        depth = np.zeros((S, N_CAPSULES, 2))
        # the same arithmetic as Camera.project and Camera.depth, with A cached
        if self.camera.distance > 0:
            ends[:, caps] = self.camera.project(e3)
        else:
            ends[:, caps] = e3 @ self._A_T + self._c
        depth[:, caps] = e3 @ self._view
        out_i = np.empty((S, 4), dtype=np.int64)
        out_f = np.empty((S, 2))
        t = self.target
        _raster.part_counts(
            ends, depth, self._rad_px, self._rad_m, SEAM_END, caps,
            float(self.camera.scale), fx.flags, fx.z, t.cost, out_i, out_f,
        )  # fmt: skip
        dA = _d_A(fx.area + out_i[:, 0], fx.inter + out_i[:, 1], t.area)
        n_e = fx.n_edge + out_i[:, 2] - out_i[:, 3]
        s_e = fx.sum_edge + out_f[:, 0] - out_f[:, 1]
        dE = _d_E(s_e, n_e, t.xi)
        return self.lambda_A * dA + self.lambda_E * dE
