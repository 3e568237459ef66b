"""The body model: skeleton tables, kinematics, part shapes, retargeting."""
