"""Stage 2: approximate temporal correspondence C and global rotations T_t' (thesis 4.5).

d(t', t) = min over sampled global rotations T of d_S(P(T(B_t)), S'_t') (eq. 4.8-4.9), then the
least-cost one-to-one monotone path through the correspondence matrix by the DP of eq. 4.11:

    D(t', t) = d(t', t) + min_{i = 1..w} D(t' - 1, t - i),       w = ceil(k L / L')

restricted to a band of half-width beta around the straight diagonal, with C(0) = C_0 (the
reference frame the first video frame shows) and C(L') = L. Thesis 6.3 suggests letting the
ends float: ``float_start`` / ``float_end`` let C(0) lie in [C_0, C_0 + f_s] and C(L') in
[L - f_e, L].

Beyond the thesis, a step cost (``slope_weight``) pulls the path's local slope towards the
mean slope L / L': without it the DP happily follows the valleys of d that long still or
repetitive stretches of a motion leave (on the public take-vs-take case its mean error was
several times larger without). With the step cost, a repeated reference frame
(a performer slower than the reference's frame rate for a moment) is allowed but expensive,
so one-to-one is the soft default rather than a hard rule (``one_to_one`` makes it hard).

Speed (beyond the thesis): images are compared at ``compare_height`` rows, d is evaluated
only inside the band, and coarse-to-fine over reference frames: the coarse pass
evaluates the cheap d_A (eq. 4.1) for every rotation sample on every ``coarse_stride``-th
reference frame and runs the same DP (same step rules and step cost, in coarse units); the
fine pass evaluates d_S on every reference frame within ``refine_radius`` of the coarse
path, only for the ``fine_samples`` rotations that were best at the nearest coarse entries,
and the final DP runs on that corridor.

    settings        AlignmentSettings, AlignmentResult
    dp              the DP (eq. 4.11): window, band, step costs, the path
    costs           rotation samples, the posed reference, targets, d(t', t) (eq. 4.8-4.9)
    correspondence  align: the stage in one call, coarse to fine
"""

from engine.stages.alignment.correspondence import align
from engine.stages.alignment.costs import (
    cost_entries,
    half_camera,
    make_targets,
    rotate_about_hip,
    rotation_samples,
)
from engine.stages.alignment.dp import band_mask, dp_path, step_costs, window_size
from engine.stages.alignment.settings import AlignmentResult, AlignmentSettings

__all__ = [
    "AlignmentResult",
    "AlignmentSettings",
    "align",
    "band_mask",
    "cost_entries",
    "dp_path",
    "half_camera",
    "make_targets",
    "rotate_about_hip",
    "rotation_samples",
    "step_costs",
    "window_size",
]
