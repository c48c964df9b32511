"""P-data: Top on hand-built polylines, invariances, mirror/reverse identities, validation errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twisted.topology import PData, PDataError, parse_p_data, top


def polyline(*xyz: tuple[float, float, float]) -> np.ndarray:
    return np.array(xyz, dtype=float)


def test_straight_rope_has_no_crossings() -> None:
    pts = np.stack([np.linspace(0, 0.84, 22), np.zeros(22), np.full(22, 0.01)], axis=1)
    assert top(pts) == PData(())
    assert top(pts).to_json() == "[]"


def test_head_over_one_crossing_sign_from_geometry() -> None:
    # head runs +x at z=0.02 over a strand running mostly -y: d_over x d_under = (1,0) x (-0.7,-2) < 0
    pts = polyline((0, 0, 0.02), (1, 0, 0.02), (1.5, 0.5, 0), (1.2, 1, 0), (0.5, -1, 0), (0.5, -1.5, 0))
    assert top(pts).to_json() == '[[1,"O",2,"-"],[2,"U",1,"-"]]'
    # same path with the head strand under: O/U swap, sign recomputed from the new over strand
    low = pts.copy()
    low[:2, 2] = -0.02
    assert top(low).to_json() == '[[1,"U",2,"+"],[2,"O",1,"+"]]'


def test_loop_in_the_other_direction_gives_positive_sign() -> None:
    # head runs +x over a strand running +y
    pts = polyline((0, 0, 0.02), (1, 0, 0.02), (1.5, -0.5, 0), (1.2, -1, 0), (0.5, -1, 0), (0.5, 1, 0))
    assert top(pts).to_json() == '[[1,"O",2,"+"],[2,"U",1,"+"]]'


def test_two_crossings_on_one_segment_are_ordered_along_it() -> None:
    # a long first segment crossed by two later vertical strands, the farther one visited first
    pts = polyline(
        (0, 0, 0.0), (4, 0, 0.0), (4, 1, 0), (3, 1, 0.02), (3, -1, 0.02), (1, -1, 0.02), (1, 1, 0.02)
    )
    p = top(pts)
    assert p.cross == 2
    # visits along the head segment: x=1 (crossed last by the tail strand) at 1, x=3 at 2
    assert p.to_list() == [[1, "U", 4, "-"], [2, "U", 3, "+"], [3, "O", 2, "+"], [4, "O", 1, "-"]]


def test_crossing_exactly_at_a_joint_counts_once() -> None:
    pts = polyline((0, 0, 0.02), (1, 0, 0.02), (2, 0, 0.02), (2, 1, 0), (1, 1, 0), (1, -1, 0))
    assert top(pts).cross == 1


def random_rope(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    angles = np.cumsum(rng.normal(0, 0.9, 21))
    steps = 0.04 * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    xy = np.concatenate([[[0.0, 0.0]], np.cumsum(steps, axis=0)])
    z = rng.uniform(0, 0.03, 22)
    return np.concatenate([xy, z[:, None]], axis=1)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    angle=st.floats(0, 2 * math.pi),
    dx=st.floats(-3, 3),
    dy=st.floats(-3, 3),
)
def test_invariant_under_translation_and_rotation_about_z(
    seed: int, angle: float, dx: float, dy: float
) -> None:
    pts = random_rope(seed)
    c, s = math.cos(angle), math.sin(angle)
    moved = pts.copy()
    moved[:, 0] = c * pts[:, 0] - s * pts[:, 1] + dx
    moved[:, 1] = s * pts[:, 0] + c * pts[:, 1] + dy
    assert top(moved) == top(pts)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_mirror_and_reverse_match_geometry(seed: int) -> None:
    pts = random_rope(seed)
    p = top(pts)
    mirrored = pts * np.array([1.0, -1.0, 1.0])
    assert top(mirrored) == p.mirror()
    assert top(pts[::-1]) == p.reverse()
    assert p.mirror().mirror() == p
    assert p.reverse().reverse() == p
    assert p.mirror().reverse() == p.reverse().mirror()
    assert parse_p_data(p.to_json()) == p


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("[[1,", "not valid JSON"),
        ('{"a": 1}', "must be a JSON list"),
        ('[[1,"O",2]]', "entry 0: expected"),
        ('[[1,"O",2,"+"]]', "must be even"),
        ('[[1,"X",2,"+"],[2,"U",1,"+"]]', "over/under"),
        ('[[1,"O",2,"*"],[2,"U",1,"*"]]', "sign must be"),
        ('[[1,"O",2,"+"],[3,"U",1,"+"]]', "positions must be exactly 1..2"),
        ('[[1,"O",3,"+"],[2,"U",1,"+"]]', "outside 1..2"),
        ('[[1,"O",1,"+"],[2,"U",2,"+"]]', "own partner"),
        ('[[1,"O",2,"+"],[2,"O",1,"+"]]', "one must be O"),
        ('[[1,"O",2,"+"],[2,"U",1,"-"]]', "signs differ"),
        ('[[1,"O",2,"+"],[2,"U",1,"+"],[3,"O",2,"+"],[4,"U",3,"+"]]', "names 1 as its partner"),
        ('[[true,"O",2,"+"],[2,"U",1,"+"]]', "position must be an integer"),
        ('[[1.5,"O",2,"+"],[2,"U",1,"+"]]', "position must be an integer"),
    ],
)
def test_malformed_p_data_is_rejected_with_its_reason(text: str, reason: str) -> None:
    with pytest.raises(PDataError, match=reason):
        parse_p_data(text)


def test_crossings_roundtrip() -> None:
    p = parse_p_data('[[1,"O",4,"-"],[2,"U",3,"+"],[3,"O",2,"+"],[4,"U",1,"-"]]')
    assert PData.from_crossings(p.crossings()) == p
    assert p.cross == 2
