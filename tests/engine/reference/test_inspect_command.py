import numpy as np

from engine.body.shapes import BodyShape
from engine.cli import main
from engine.io import write_bvh


def test_inspect_cmu_prints_mapping_and_segments(cmu_bvh, tmp_path, capsys):
    png = tmp_path / "r.png"
    assert main(["reference", "inspect", str(cmu_bvh), "--plot", str(png)]) == 0
    out = capsys.readouterr().out
    assert "580 at 120.000 fps" in out
    assert "Neck1 -> neck" in out and "Head/End -> head_top" in out
    assert "frame 0 is a conversion T-pose" in out
    assert "frames   274 -   473" in out
    assert png.stat().st_size > 10_000


def test_inspect_shows_the_segments_a_domain_file_sets(cmu_bvh, tmp_path, capsys):
    bvh = tmp_path / "swing.bvh"
    bvh.write_bytes(cmu_bvh.read_bytes())
    (tmp_path / "swing.domain.json").write_text('{"segments": [1, 100, 300]}')
    assert main(["reference", "inspect", str(bvh)]) == 0
    out = capsys.readouterr().out
    assert "segments    3 (set by swing.domain.json)" in out
    assert "frames   100 -   300" in out and "frames   300 -   579" in out
    (tmp_path / "swing.domain.json").write_text('{"segments": [1, 100, 900]}')
    assert main(["reference", "inspect", str(bvh)]) == 2
    assert "domain segments" in capsys.readouterr().err


def test_inspect_bad_file_is_one_line_error(tmp_path, capsys):
    p = tmp_path / "x.bvh"
    p.write_text("not a bvh\n")
    assert main(["reference", "inspect", str(p)]) == 2
    assert "is not a BVH file" in capsys.readouterr().err


def test_inspect_own_export(tmp_path, capsys):
    shape = BodyShape.default()
    from engine.body.kinematics import forward_kinematics

    J = forward_kinematics(
        shape.offsets, np.zeros((3, 3)), np.broadcast_to(np.eye(3), (3, 12, 3, 3))
    )
    p = write_bvh(tmp_path / "o.bvh", J, 30.0, shape)
    assert main(["reference", "inspect", str(p), "--threshold-deg", "90"]) == 0
    assert "name table 'coach'" in capsys.readouterr().out
