"""References from several takes (seed 002): aSpace, median take, far takes, the model, z."""

import json

import numpy as np
import pytest

from engine.cli import main
from engine.errors import InvalidInput
from engine.io.bvh import load_reference
from engine.reference.action_model import Take, build_action_model, motion_direction
from engine.reference.domain import check_variation, find_domain, parse_domain
from engine.reference.posture_space import POSTURE_DIMS, ActionSpace, posture_vectors
from engine.reference.synchronisation import interpolate
from tests.conftest import CMU


def cmu_take(name: str) -> Take:
    path = CMU / f"{name}.bvh"
    if not path.exists():
        pytest.skip("../shared/data/cmu is not beside the clone")
    return Take.from_reference(load_reference(path))


def warped(take: Take, amplitude: float, name: str) -> Take:
    """``take`` replayed with a smooth warp of the given signed amplitude."""
    P = len(take.joints)
    u = np.linspace(0.0, 1.0, P)
    src = (u + amplitude * np.sin(2 * np.pi * u) / (2 * np.pi)) * (P - 1)
    return Take(name, interpolate(take.joints, src), take.fps, take.shape, take.tpose)


def test_posture_vectors_are_unit_direction_cosines_and_pelvis_height():
    t = cmu_take("64_29")
    psi = posture_vectors(t.joints, t.shape.offsets)
    assert psi.shape == (len(t.joints), POSTURE_DIMS)
    assert np.allclose(np.linalg.norm(psi[:, 1:].reshape(-1, 16, 3), axis=-1), 1.0)
    u = psi[:, 0]
    assert 0.5 < u[0] < 1.5 and u.min() < u[0]  # standing, then bending down


def test_action_space_keeps_the_smallest_dimension_reaching_the_share(rng):
    X = rng.normal(size=(500, 5)) * np.array([10.0, 3.0, 1.0, 0.1, 0.1])
    space = ActionSpace.fit(X, share=0.95)
    assert space.dims == 2 and space.explained >= 0.95
    assert ActionSpace.fit(X, share=0.999).dims > 2
    assert space.project(X).shape == (500, 2)
    with pytest.raises(InvalidInput):
        ActionSpace.fit(X[:1])


def test_the_median_of_warps_of_one_take_is_the_least_warped():
    base = cmu_take("63_01")
    amplitudes = [0.45, -0.4, 0.05, 0.35, -0.3]
    takes = [warped(base, a, f"w{a:+.2f}") for a in amplitudes]
    model = build_action_model(takes)
    assert model.names[model.median] == "w+0.05"
    assert model.kept.all() and not model.warnings
    assert model.mean_joints.shape == (len(base.joints), 17, 3)
    # every take, warped back onto the median, shows the same postures: little spread
    assert np.degrees(model.bone_sd).mean() < 2.0


def test_a_squat_among_golf_swings_is_left_out_and_named():
    takes = [cmu_take(n) for n in ("63_01", "63_02", "63_07", "64_17")]
    model = build_action_model(takes)
    assert list(model.kept) == [True, True, True, False]
    assert len(model.warnings) == 1 and "64_17" in model.warnings[0]
    assert "another action" in model.warnings[0]


def test_two_takes_of_different_actions_are_refused():
    with pytest.raises(InvalidInput, match="fewer than two takes of one action"):
        build_action_model([cmu_take("63_01"), cmu_take("64_17")])
    with pytest.raises(InvalidInput, match="at least two"):
        build_action_model([cmu_take("63_01")])


def test_the_model_of_two_bend_downs_spreads_where_they_differ():
    model = build_action_model([cmu_take("64_29"), cmu_take("64_30")])
    sd = np.degrees(model.bone_sd)
    assert sd.shape == (len(model.mean_joints), 16)
    assert np.isfinite(sd).all() and 0.5 < sd.mean() < 10.0
    assert model.direction.shape == model.mean_x.shape
    assert np.allclose(np.linalg.norm(model.direction, axis=1), 1.0)


def test_motion_direction_averages_the_last_unit_steps():
    x = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, 1.0]])
    v = motion_direction(x, window=2)
    assert np.allclose(v[1], [1, 0]) and np.allclose(v[3], np.array([1, 1]) / np.sqrt(2))


def test_z_scores_are_finite_when_the_spread_is_zero():
    doc = {"variation": {"bone_sd_deg": [[0.0] * 16] * 4, "sd_floor_deg": 2.0}}
    domain = parse_domain(doc)
    z = domain.z_scores(np.radians(np.full((3, 16), 4.0)), np.array([0, 1, 3]))
    assert np.isfinite(z).all() and np.allclose(z, 2.0)


@pytest.mark.parametrize(
    "variation, match",
    [
        ({"bone_sd_deg": [[1.0] * 15]}, "16 numbers"),
        ({"bone_sd_deg": [[-1.0] * 16]}, "16 numbers"),
        ({"bone_sd_deg": "x"}, "16 numbers"),
        ({"bone_sd_deg": [[1.0] * 16], "sd_floor_deg": 0}, "positive"),
        ({"sd": [[1.0] * 16]}, "bone_sd_deg"),
    ],
)
def test_a_bad_variation_is_refused_by_name(variation, match):
    with pytest.raises(InvalidInput, match=match):
        parse_domain({"variation": variation})


def test_build_command_writes_a_reference_that_analyses_read(tmp_path, capsys):
    for n in ("64_29", "64_30"):
        if not (CMU / f"{n}.bvh").exists():
            pytest.skip("../shared/data/cmu is not beside the clone")
    out = tmp_path / "bend"
    png = tmp_path / "sync.png"
    args = ["reference", "build", str(CMU / "64_29.bvh"), str(CMU / "64_30.bvh"),
            "--out", str(out), "--plot", str(png), "--sport", "fitness"]  # fmt: skip
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "median take" in text and "spread of the expert's bones" in text
    ref = load_reference(out.with_suffix(".bvh"))
    assert ref.has_tpose  # the median's T-pose is kept: frames numbered as in its file
    domain = find_domain(out.with_suffix(".bvh"))
    assert domain is not None and domain.bone_sd is not None and domain.sport == "fitness"
    check_variation(ref.motion, domain)
    summary = json.loads(str(np.load(tmp_path / "bend.model.npz")["summary"]))
    assert summary["kept"] == ["64_29", "64_30"]
    assert png.stat().st_size > 10_000


def test_build_command_refuses_one_take_and_unreadable_files(tmp_path, capsys):
    bad = tmp_path / "x.bvh"
    bad.write_text("not a bvh\n")
    assert main(["reference", "build", str(bad), "--out", str(tmp_path / "r")]) == 2
    assert "at least two takes" in capsys.readouterr().err
    assert main(["reference", "build", str(bad), str(bad), "--out", str(tmp_path / "r")]) == 2
    assert "is not a BVH file" in capsys.readouterr().err


def test_a_variation_built_for_another_reference_is_refused():
    t = cmu_take("64_29")
    domain = parse_domain({"variation": {"bone_sd_deg": [[1.0] * 16] * 10}})
    from engine.types import Motion

    with pytest.raises(InvalidInput, match="another reference"):
        check_variation(Motion(joints=t.joints, fps=t.fps), domain)
