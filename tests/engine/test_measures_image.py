"""d_A, d_E, d_S (thesis 4.4.1, eq. 4.1-4.4) on hand-built masks."""

from __future__ import annotations

import numpy as np
import pytest

from engine import measures
from engine.errors import InvalidInput


def _box(H: int, W: int, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
    m = np.zeros((H, W), dtype=bool)
    m[r0:r1, c0:c1] = True
    return m


def test_d_A_hand_values() -> None:
    a = _box(10, 10, 0, 10, 0, 5)  # 50 px
    b = _box(10, 10, 0, 10, 2, 7)  # 50 px, 30 in common
    assert measures.d_A(a, b) == pytest.approx(1 - 2 * 30 / 100)
    assert measures.d_A(a, a) == 0.0
    assert measures.d_A(a, ~a) == 1.0


def test_edge_cost_map_is_truncated_squared_distance() -> None:
    e = np.zeros((5, 12), dtype=bool)
    e[:, 0] = True
    cost = measures.edge_cost_map(e, sigma_px=2.0, xi=3.0)
    np.testing.assert_allclose(cost[2, :5], [0.0, 0.25, 1.0, 2.25, 3.0], atol=1e-5)
    assert cost.max() == pytest.approx(3.0)
    assert np.all(measures.edge_cost_map(np.zeros((3, 3), bool), xi=0.5) == 0.5)


def test_d_E_is_mean_truncated_chamfer() -> None:
    target = np.zeros((8, 20), dtype=bool)
    target[:, 2] = True
    edges = np.zeros_like(target)
    edges[1, 2] = True  # distance 0
    edges[1, 5] = True  # distance 3 -> 9 / sigma^2 = 1 (sigma 3)
    edges[1, 19] = True  # distance 17 -> truncated to xi
    got = measures.d_E(edges, target, sigma_px=3.0, xi=1.5)
    assert got == pytest.approx((0.0 + 1.0 + 1.5) / 3, abs=1e-5)
    assert measures.d_E(np.zeros_like(target), target, xi=1.5) == 1.5  # nothing rendered


def test_d_S_combines_with_weights() -> None:
    sil = _box(20, 20, 5, 15, 5, 15)
    tsil = _box(20, 20, 5, 15, 7, 17)
    edges = sil & ~_box(20, 20, 6, 14, 6, 14)
    tedges = tsil & ~_box(20, 20, 6, 14, 8, 16)
    dA = measures.d_A(sil, tsil)
    dE = measures.d_E(edges, tedges, sigma_px=4.0, xi=1.0)
    assert 0 < dA < 1 and 0 < dE < 1
    got = measures.d_S(sil, edges, tsil, tedges, lambda_A=2.0, lambda_E=0.5, sigma_px=4.0)
    assert got == pytest.approx(2.0 * dA + 0.5 * dE)
    assert measures.d_S(sil, edges, sil, edges) == 0.0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: measures.edge_cost_map(np.zeros(4, bool)), "edges"),
        (lambda: measures.edge_cost_map(np.zeros((4, 4), bool), sigma_px=0.0), "sigma_px"),
        (lambda: measures.edge_cost_map(np.zeros((4, 4), bool), xi=-1.0), "xi"),
        (lambda: measures.d_E(np.zeros((4, 4), bool), np.zeros((4, 5), bool)), "shape"),
        (
            lambda: measures.d_S(*(np.zeros((4, 4), bool),) * 2, *(np.zeros((5, 4), bool),) * 2),
            "target_sil",
        ),
    ],
)
def test_bad_inputs_raise(call, match: str) -> None:  # noqa: ANN001
    with pytest.raises(InvalidInput, match=match):
        call()
