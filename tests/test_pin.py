"""Two-hand curves (docs/DESIGN.md section 3.6): a second hand holds, places or carries one link."""

from __future__ import annotations

import numpy as np
import pytest

from twisted.sim import N_LINKS, Curve, RopeSim, simulate
from twisted.sim.rope import PIN_SLIP_M, Pin

# on the straight rope: link 13 carried around link 8, counter-clockwise, and over the rope beside it (its
# neighbours 12, -0.1, -0.05 and -0.1 make the same curl)
LOOP = Curve(13, 0.05, -0.1, -0.05, Pin(8, around=1))


class PinWatch(RopeSim):
    """The simulator, recording the pinned link's pose after every step while the second hand holds it."""

    def __init__(self) -> None:
        super().__init__()
        self.poses: list[tuple[np.ndarray, np.ndarray]] = []

    def step(self) -> str | None:
        reason = super().step()
        held = self.pinned_link()
        if held is not None:
            body = self._link_body[held]
            self.poses.append((self.data.xpos[body].copy(), self.data.xquat[body].copy()))
        return reason


@pytest.fixture(scope="module")
def sim() -> PinWatch:
    return PinWatch()


def _turn_deg(quats: np.ndarray) -> float:
    return float(np.degrees(2 * np.arccos(np.clip(np.abs(quats @ quats[0]), 0, 1))).max())


def test_a_pinned_link_does_not_move_while_pinned(sim: PinWatch) -> None:
    sim.reset()
    start = sim.link_positions()[8].copy()
    sim.poses.clear()
    out = sim.apply(LOOP)
    assert out.ok, out.reason
    assert sim.pinned_link() is None  # let go with the active link
    pos = np.array([p for p, _ in sim.poses])
    quat = np.array([q for _, q in sim.poses])
    assert len(pos) > 50  # held through the whole carry
    # the weld is a soft constraint: the link stays within a few mm and a degree of where it lay
    assert float(np.linalg.norm(pos - start, axis=1).max()) < PIN_SLIP_M
    assert _turn_deg(quat) < 2.0
    assert sim.p_data().cross == 1  # the carried link made a curl around the held one


def test_a_carry_that_pulls_the_rope_taut_between_the_hands_is_rejected(sim: PinWatch) -> None:
    sim.reset()
    sim.poses.clear()
    out = sim.apply(Curve(9, 0.02, 0.0, 0.4, Pin(8)))  # a neighbour carried 40 cm away
    assert not out.ok and "taut" in str(out.reason)
    pos = np.array([p for p, _ in sim.poses])
    assert float(np.linalg.norm(pos - pos[0], axis=1).max()) < 2 * PIN_SLIP_M


def test_pick_place_hold_and_both_hands_carrying(sim: PinWatch) -> None:
    sim.reset()
    start = sim.link_positions()[8].copy()
    sim.poses.clear()
    out = sim.apply(Curve(13, 0.05, -0.2, 0.0, Pin(8, "place", 0.0, 0.0, 0.06)))
    assert out.ok, out.reason
    held_after_place = np.array([p for p, _ in sim.poses])[-1]
    assert abs(held_after_place[1] - start[1] - 0.06) < 0.01  # held where it was placed
    sim.reset()
    out = sim.apply(Curve(12, 0.05, 0.0, 0.1, Pin(9, "carry", 0.0, 0.0, 0.1, turn_rad=0.3)))
    assert out.ok, out.reason
    assert float(sim.link_positions()[9][1]) > 0.05  # the second hand carried its link too


def test_two_hand_curves_are_deterministic_and_one_hand_curves_unchanged(sim: PinWatch) -> None:
    sim.reset()
    q0 = sim.state()
    a, b = simulate(sim, q0, LOOP), simulate(RopeSim(), q0, LOOP)
    assert a.ok and b.ok and a.p_data == b.p_data and np.array_equal(a.state, b.state)
    plain = Curve(13, 0.05, -0.1, -0.05)
    assert plain == Curve(13, 0.05, -0.1, -0.05, None) and plain.pin is None
    assert np.array_equal(plain.to_array(), [13, 0.05, -0.1, -0.05])
    with pytest.raises(ValueError, match="no 4-number array"):
        LOOP.to_array()


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: Curve(8, 0.02, 0.1, 0.1, Pin(8)), "pinned link 8 is the curve's active link"),
        (lambda: Pin(N_LINKS), f"the pinned link must be in 0..{N_LINKS - 1}, got {N_LINKS}"),
        (lambda: Pin(-1), "the pinned link must be in 0"),
        (lambda: Pin(3.0), "the pinned link must be an integer"),  # type: ignore[arg-type]
        (lambda: Pin(3, "grab"), "pin mode must be one of hold, place, carry"),
        (lambda: Pin(3, x_m=0.1), "a held pin does not move"),
        (lambda: Pin(3, around=2), "pin around must be -1, 0 or \\+1"),
        (lambda: Pin(3, "carry", y_m=float("nan")), "must be finite"),
        (lambda: Curve(2, 0.0, 0.1, 0.1, 5), "a curve's pin must be a Pin"),  # type: ignore[arg-type]
    ],
)
def test_bad_pins_are_refused_with_a_clear_message(make: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make()  # type: ignore[operator]
