"""Seed 002's synchronisation: identity, shifts, warps, DTW at mu = 0, validation."""

import numpy as np
import pytest

from engine.errors import InvalidInput
from engine.reference.synchronisation import (
    dsi_costs,
    interpolate,
    optimal_disparity,
    rule_of_thumb_mu,
    stretch,
    synchronise,
    warp,
)


def rest_motion_rest(frames: int = 200) -> np.ndarray:
    """(F, 3): still, then a smooth motion through distinct postures, then still."""
    t = np.linspace(0.0, 1.0, frames)
    s = np.clip((t - 0.2) / 0.6, 0.0, 1.0)
    s = s * s * (3 - 2 * s)  # eased 0 -> 1
    return np.stack([np.sin(3 * s), np.cos(5 * s), 2 * s], axis=1)


def moving_frames(x: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.gradient(x, axis=0), axis=1) > 1e-3


def test_a_take_synchronised_to_itself_has_zero_disparity():
    x = rest_motion_rest()
    for mu in (None, 0.0, 5.0):
        s = synchronise(x, x, mu=mu)
        assert np.all(s.disparity == 0)
        assert s.cost == pytest.approx(0.0, abs=1e-12)
        assert s.alpha == 1.0


def test_a_constant_shift_is_recovered_where_the_take_moves():
    x = rest_motion_rest(240)
    shift = 9
    delayed = np.concatenate([np.repeat(x[:1], shift, axis=0), x[:-shift]])  # same length
    s = synchronise(x, delayed)
    moving = moving_frames(x)
    assert np.all(s.disparity[moving] == shift)
    assert s.disparity[0] == 0 and s.disparity[-1] == 0  # eq. 9: both ends pinned
    assert np.abs(s.positions - (np.arange(240) + shift))[moving].max() < 0.01  # sub-frame
    assert np.allclose(warp(delayed, s)[moving], x[moving], atol=1e-3)


@pytest.mark.parametrize(
    "mu, refine, mean_frames, max_frames",
    [(0.0, False, 0.5, 1.0), (None, False, 2.0, 4.0), (None, True, 0.2, 1.0)],
)
def test_a_known_smooth_warp_is_recovered(mu, refine, mean_frames, max_frames):
    """DTW recovers a noise-free warp within a frame; seed 002's smoothness term alone (eq.
    20's mu) cuts the corners of a warp whose rate changes, by up to a few frames; the
    sub-frame refinement after it lands on the warp (benchmarks/README.md)."""
    x = rest_motion_rest(300)
    F = 330
    u = np.linspace(0.0, 1.0, F)
    src = (u + 0.3 * np.sin(2 * np.pi * u) / (2 * np.pi)) * (len(x) - 1)  # pattern frame shown
    take = interpolate(x, src)
    truth = np.interp(np.arange(len(x)), src, np.arange(F, dtype=float))
    s = synchronise(x, take, mu=mu, refine=refine)
    err = np.abs(s.positions - truth)[moving_frames(x)]
    assert err.mean() <= mean_frames and err.max() <= max_frames
    assert np.all(np.diff(s.positions) >= 0)  # time never runs backwards


def test_the_smoothness_term_gives_a_smoother_warp_than_dtw(rng):
    x = rest_motion_rest(240)
    noisy = x + rng.normal(0.0, 0.02, x.shape)
    dtw = synchronise(x, noisy, mu=0.0)
    smooth = synchronise(x, noisy, refine=False)  # eq. 20
    refined = synchronise(x, noisy)
    assert smooth.mu > 0
    assert refined.roughness < smooth.roughness < dtw.roughness
    assert np.all(np.diff(refined.positions) >= 0)
    assert refined.positions[0] == 0 and refined.positions[-1] == len(noisy) - 1


def plain_dtw(E: np.ndarray) -> float:
    """Textbook DTW over the full cost matrix E[p, q], with q advancing by 0, 1 or 2 frames
    per frame p, from (0, 0) to (P-1, P-1): an independent reference implementation."""
    P = len(E)
    D = np.full((P, P), np.inf)
    D[0, 0] = E[0, 0]
    for p in range(1, P):
        for q in range(P):
            best = min(D[p - 1, q], D[p - 1, q - 1] if q >= 1 else np.inf,
                       D[p - 1, q - 2] if q >= 2 else np.inf)  # fmt: skip
            D[p, q] = E[p, q] + best
    return float(D[-1, -1])


def test_mu_zero_is_dtw(rng):
    for _ in range(3):
        xn, xm = rng.normal(size=(30, 2)), rng.normal(size=(30, 2))
        full = ((xn[:, None] - xm[None]) ** 2).sum(-1)
        E = dsi_costs(xn, xm, len(xn) - 1)
        d, total = optimal_disparity(E, 0.0)
        assert total == pytest.approx(plain_dtw(full))
        path = np.arange(30) + d
        assert full[np.arange(30), path].sum() == pytest.approx(total)
        assert np.all(np.diff(path) >= 0) and np.all(np.diff(path) <= 2)


def test_rule_of_thumb_is_the_mean_cost_one_frame_off_the_linear_path():
    E = np.array([[np.inf, 0.0, 2.0], [1.0, 3.0, 5.0], [4.0, 6.0, np.inf]])
    assert rule_of_thumb_mu(E) == pytest.approx(np.mean([0, 2, 1, 3, 5, 4, 6]))


def test_stretch_keeps_both_ends():
    x = np.arange(10.0)[:, None]
    y = stretch(x, 19)
    assert y[0, 0] == 0 and y[-1, 0] == 9 and y[1, 0] == pytest.approx(0.5)


@pytest.mark.parametrize(
    "xn, xm, kw, match",
    [
        (np.zeros((5, 2)), np.zeros((5, 3)), {}, "alike"),
        (np.zeros((1, 2)), np.zeros((5, 2)), {}, "two frames"),
        (np.zeros((5, 2)), np.zeros((5, 2)), {"mu": -1.0}, "mu"),
        (np.zeros((5, 2)), np.zeros((5, 2)), {"band": 0.0}, "band"),
    ],
)
def test_bad_input_is_refused(xn, xm, kw, match):
    with pytest.raises(InvalidInput, match=match):
        synchronise(xn, xm, **kw)
