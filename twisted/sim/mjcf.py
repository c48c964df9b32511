"""MJCF of the rope and the gripper (docs/DESIGN.md section 2), built in code once per simulator.

The rope is an explicit body chain (no ``composite``, no plugin): ``ROPE.n_links`` (21 by default) capsule
links (``twisted.rope``, ``TWISTED_ROPE``) whose body frames sit at the link centres with the local x axis
pointing from the head (link 0) towards the tail (the last link). The middle link carries the free joint
and both halves hang off it, which keeps the kinematic tree shallow (a chain rooted at one end costs about
three times more per step).
Each joint between neighbours is two hinges at the shared end point: yaw about local z and pitch
about local y, with the stiffness, damping, armature and limits measured to work in MuJoCo 4.

The gripper is a mocap body without a geom (it can never collide with the rope) and one
pre-declared weld equality per link, all inactive; the simulator switches one on through
``data.eq_active``. Each weld's ``relpose`` is the identity, so welding pins the link's frame to
the gripper's frame: the simulator puts the mocap body exactly at the link before switching on.
"""

from __future__ import annotations

from dataclasses import dataclass

# the link count and spacing (centre to centre) of the one rope: twisted.rope.ROPE
from twisted.rope import LINK_SPACING_M, N_LINKS

MIDDLE_LINK = N_LINKS // 2

LINK_RADIUS_M = 0.01
LINK_HALF_LENGTH_M = 0.015  # capsule cylinder half-length; the caps overlap the neighbours
FRICTION = (1.0, 0.005, 0.0001)  # MuJoCo's default (sliding, torsional, rolling)


@dataclass(frozen=True)
class RopeParams:
    """Physical and numerical settings of the rope model (defaults: docs/DESIGN.md section 2.4)."""

    timestep_s: float = 0.005
    friction_scale: float = 1.0
    joint_stiffness: float = 2e-3  # N m / rad, keeps short kinks from persisting
    joint_damping: float = 3e-4  # higher damping makes the rope creep for seconds
    joint_armature: float = 1e-5
    joint_limit_deg: float = 110.0  # without limits an end link folds onto its neighbour
    weld_solref: tuple[float, float] = (0.02, 1.0)
    # the second hand's welds (two-hand curves, docs/DESIGN.md section 3.6)
    pin_weld_solref: tuple[float, float] = (0.01, 1.0)
    pin_weld_solimp: tuple[float, float, float] = (0.95, 0.99, 0.001)
    pin_weld_torquescale: float = 10.0
    # Twice as stiff as MuJoCo's default (0.02 s) and still 2 x timestep: with the default a strand
    # dragged at low height sank over a radius deep into another one or into the table in ~1 % of
    # random curves; with 0.01 s none in 400, at the same cost.
    contact_solref: tuple[float, float] = (0.01, 1.0)
    contact_solimp: tuple[float, float, float] = (0.9, 0.95, 0.001)  # MuJoCo's default
    # The capsules' radius and density (MuJoCo's default, 1000 kg/m^3: a link of about 0.0136 kg). The
    # planner's rope keeps these; a world apart from it (twisted.world) draws others per episode.
    link_radius_m: float = LINK_RADIUS_M
    link_density_kg_m3: float = 1000.0


def link_name(i: int) -> str:
    return f"link_{i}"


def joint_names(i: int) -> tuple[str, str]:
    """The (yaw, pitch) hinge names of the joint between link ``i`` and link ``i + 1``."""
    return f"yaw_{i}", f"pitch_{i}"


def weld_name(i: int) -> str:
    return f"grasp_{i}"


def _fmt(*values: float) -> str:
    return " ".join(f"{v:.10g}" for v in values)


def _hinges(i: int, anchor_x: float) -> str:
    """The two hinges of joint ``i`` (between links i and i+1), anchored at local x = ``anchor_x``."""
    yaw, pitch = joint_names(i)
    pos = _fmt(anchor_x, 0.0, 0.0)
    return (
        f'<joint name="{yaw}" class="rope" pos="{pos}" axis="0 0 1"/>'
        f'<joint name="{pitch}" class="rope" pos="{pos}" axis="0 1 0"/>'
    )


def _link_geom(i: int) -> str:
    # Along local x; the end points are read from the joint anchors, never from the geom's axis
    # (a ``fromto`` capsule's local z runs from "to" back to "from", docs/DESIGN.md section 2.5).
    h = LINK_HALF_LENGTH_M
    return f'<geom name="{link_name(i)}" class="rope" fromto="{_fmt(-h, 0, 0, h, 0, 0)}"/>'


def _chain(i: int, step: int) -> str:
    """Link ``i`` and, nested inside it, the rest of the half-rope in direction ``step`` (+1 or -1).

    A link is placed one spacing from its parent; the joint sits at the shared end point, half a
    spacing back towards the parent. For the tail half (step +1) joint ``i - 1`` joins links i-1
    and i; for the head half (step -1) joint ``i`` joins links i and i+1.
    """
    if not 0 <= i < N_LINKS:
        return ""
    half = LINK_SPACING_M / 2
    joint = _hinges(i - 1, -half) if step > 0 else _hinges(i, half)
    pos = _fmt(step * LINK_SPACING_M, 0, 0)
    return f'<body name="{link_name(i)}" pos="{pos}">{joint}{_link_geom(i)}{_chain(i + step, step)}</body>'


TAIL_GRIPPER = "tail_gripper"
TAIL_WELD = "hold_tail"
# the second hand of a two-hand curve (docs/DESIGN.md section 3.6): a mocap body and one weld per link
PIN_GRIPPER = "pin_gripper"


def pin_weld_name(i: int) -> str:
    return f"pin_{i}"


def rope_xml(params: RopeParams = RopeParams(), tail_gripper: bool = False) -> str:
    """The MJCF text of the straight rope along x, centred at the origin, resting on the table.

    ``tail_gripper`` adds a second mocap body and one inactive weld of it to the tail link (the pull
    test of :mod:`twisted.tighten` holds the head with the first gripper, the tail with this one).
    Every model has a third mocap body, the second hand of a two-hand curve (:data:`PIN_GRIPPER`), with
    one inactive weld to each link (:func:`pin_weld_name`); it comes after the rope and its welds after
    the others, so every other id is what it was without it. No mocap body adds a degree of freedom:
    states are the same vectors in every model.
    """
    mu = _fmt(*(f * params.friction_scale for f in FRICTION))
    lim = params.joint_limit_deg
    welds = "".join(
        f'<weld name="{weld_name(i)}" body1="gripper" body2="{link_name(i)}" active="false" '
        f'relpose="0 0 0 1 0 0 0" solref="{_fmt(*params.weld_solref)}"/>'
        for i in range(N_LINKS)
    )
    second = ""
    if tail_gripper:
        second = f'<body name="{TAIL_GRIPPER}" mocap="true" pos="0 0 0.5"/>'
        welds += (
            f'<weld name="{TAIL_WELD}" body1="{TAIL_GRIPPER}" body2="{link_name(N_LINKS - 1)}" '
            f'active="false" '
            f'relpose="0 0 0 1 0 0 0" solref="{_fmt(*params.weld_solref)}"/>'
        )
    welds += "".join(
        f'<weld name="{pin_weld_name(i)}" body1="{PIN_GRIPPER}" body2="{link_name(i)}" active="false" '
        f'relpose="0 0 0 1 0 0 0" solref="{_fmt(*params.pin_weld_solref)}" '
        f'solimp="{_fmt(*params.pin_weld_solimp)}" torquescale="{params.pin_weld_torquescale:g}"/>'
        for i in range(N_LINKS)
    )
    middle = (
        f'<body name="{link_name(MIDDLE_LINK)}" pos="{_fmt(0, 0, params.link_radius_m)}">'
        f'<freejoint name="root"/>{_link_geom(MIDDLE_LINK)}'
        f"{_chain(MIDDLE_LINK - 1, -1)}{_chain(MIDDLE_LINK + 1, +1)}</body>"
    )
    return f"""<mujoco model="twisted_rope">
  <compiler angle="degree"/>
  <option timestep="{params.timestep_s:.10g}" integrator="implicitfast" solver="Newton" cone="pyramidal"
          jacobian="sparse"/>
  <default>
    <geom friction="{mu}" condim="3" solref="{_fmt(*params.contact_solref)}"
          solimp="{_fmt(*params.contact_solimp)}"/>
    <default class="rope">
      <joint type="hinge" stiffness="{params.joint_stiffness:.10g}" damping="{params.joint_damping:.10g}"
             armature="{params.joint_armature:.10g}" limited="true" range="{_fmt(-lim, lim)}"/>
      <geom type="capsule" size="{_fmt(params.link_radius_m)}" density="{params.link_density_kg_m3:.10g}"
            rgba="0.8 0.3 0.2 1"/>
    </default>
  </default>
  <worldbody>
    <geom name="table" type="plane" size="0 0 0.05" rgba="0.6 0.6 0.6 1"/>
    <light pos="0 0 2" dir="0 0 -1"/>
    <body name="gripper" mocap="true" pos="0 0 0.5">
      <site name="gripper" size="0.005" rgba="0.1 0.6 0.1 0.5"/>
    </body>
    {second}
    {middle}
    <body name="{PIN_GRIPPER}" mocap="true" pos="0 0 0.6"/>
  </worldbody>
  <equality>{welds}</equality>
</mujoco>
"""
