"""The mesh renderer puts the body where Camera.project says, with the capsules' silhouette."""

from __future__ import annotations

import numpy as np
import pytest

from engine.body.kinematics import forward_kinematics, rotation_about_axis
from engine.body.shapes import BodyShape, capsule_endpoints
from engine.errors import InvalidInput
from engine.render.camera import Camera
from engine.render.mesh import MeshRenderer, textured_background

W, H = 160, 120


def _posture(shape: BodyShape) -> np.ndarray:
    R = np.broadcast_to(np.eye(3), (12, 3, 3)).copy()
    z = np.array([0.0, 0.0, 1.0])
    R[4] = rotation_about_axis(z, -1.1)  # left upper arm down-ish
    R[5] = rotation_about_axis(np.array([1.0, 0.0, 0.0]), 1.2)  # left forearm forward
    R[6] = rotation_about_axis(z, 0.9)
    R[10] = rotation_about_axis(np.array([1.0, 0.0, 0.0]), -0.4)  # right thigh forward
    return forward_kinematics(shape.offsets, np.array([0.1, 0.95, -0.2]), R)


def _capsule_mask(joints: np.ndarray, shape: BodyShape, cam: Camera) -> np.ndarray:
    """Brute force: pixels whose centre is within radius of a projected capsule axis."""
    ends = cam.project(capsule_endpoints(joints))  # (C, 2, 2)
    r = np.asarray(shape.radii) * cam.scale
    v, u = np.mgrid[0:H, 0:W]
    p = np.stack([u, v], -1).astype(float)[:, :, None, :]  # (H, W, 1, 2)
    a, b = ends[:, 0], ends[:, 1]
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, -1) / np.maximum(np.sum(ab * ab, -1), 1e-12), 0, 1)
    d = np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)
    return np.any(d <= r, axis=-1)


@pytest.fixture(scope="module")
def renderer():
    with MeshRenderer(W, H) as r:
        yield r


@pytest.mark.parametrize(("azimuth", "theta_z"), [(0.0, 0.0), (0.9, 0.15), (np.pi / 2, -0.1)])
def test_mesh_matches_projection_and_capsules(renderer, azimuth, theta_z):
    shape = BodyShape.default(1.75)
    joints = _posture(shape)
    cam = Camera(scale=55.0, theta_z=theta_z, cx=81.3, cy=112.7, azimuth=azimuth, width=W, height=H)
    bg = textured_background(H, W, np.random.default_rng(0))
    img, mask = renderer.render(joints, shape, cam, background=bg)
    assert img.shape == (H, W, 3) and img.dtype == np.uint8 and mask.shape == (H, W)

    uv = cam.project(joints)
    for j in (0, 3, 6, 16):  # hip, ankles, head top: inside the body mask
        u, v = np.rint(uv[j]).astype(int)
        assert mask[v, u], f"joint {j} at {(u, v)} outside the rendered body"
    # and the background is untouched far from the body
    assert not np.any(mask & _far_from_body(joints, shape, cam))
    assert np.array_equal(img[~mask], bg[~mask])

    ref = _capsule_mask(joints, shape, cam)
    iou = np.count_nonzero(ref & mask) / np.count_nonzero(ref | mask)
    assert iou >= 0.9, iou
    print(f"IoU {iou:.3f}")


def _far_from_body(joints, shape, cam) -> np.ndarray:
    """Pixels more than 3 px from every capsule."""
    fat = BodyShape(offsets=shape.offsets, radii=np.asarray(shape.radii) + 3.0 / cam.scale)
    return ~_capsule_mask(joints, fat, cam)


def test_mesh_follows_the_camera_centre(renderer):
    shape = BodyShape.default(1.7)
    joints = _posture(shape)
    cam = Camera(scale=50.0, cx=60.0, cy=110.0, width=W, height=H)
    _, m1 = renderer.render(joints, shape, cam)
    _, m2 = renderer.render(joints, shape, cam.with_(cx=80.0))
    c1 = np.argwhere(m1).mean(0)
    c2 = np.argwhere(m2).mean(0)
    np.testing.assert_allclose(c2 - c1, [0.0, 20.0], atol=0.3)


def test_render_rejects_bad_inputs(renderer):
    shape = BodyShape.default()
    cam = Camera(scale=50.0, width=W, height=H)
    with pytest.raises(InvalidInput, match="joints"):
        renderer.render(np.zeros((16, 3)), shape, cam)
    with pytest.raises(InvalidInput, match="camera is"):
        renderer.render(_posture(shape), shape, cam.with_(width=200))
    with pytest.raises(InvalidInput, match="background"):
        renderer.render(_posture(shape), shape, cam, background=np.zeros((H, W), np.uint8))


def test_background_is_reproducible_and_textured():
    a = textured_background(H, W, np.random.default_rng(5))
    b = textured_background(H, W, np.random.default_rng(5))
    c = textured_background(H, W, np.random.default_rng(6))
    assert a.shape == (H, W, 3) and a.dtype == np.uint8
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a.std() > 5.0
