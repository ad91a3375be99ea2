"""Geometries of the reference scenes of ``shared/cases.md``, as :class:`fdem.geometry.Geometry` objects.

Where a paper is silent the choice is a keyword argument with the assumed default, named in
the docstring, so a case script can expose it.
"""
from __future__ import annotations

import math

import numpy as np

from .geometry import BrickSet, Geometry, IntermittentSet, SegmentSet, rectangle, simple_slope

FOUR_SLOPE_HEIGHT = 15.0
FOUR_SLOPE_FACE_ANGLE = 45.0
FOUR_SLOPE_JOINT_DIP = {"low": 15.0, "high": 115.0}
FOUR_SLOPE_SPACING = {"fine": 1.0, "coarse": 5.0}


def four_slope_model(angle: str = "low", spacing: str | float = "fine", toe_length: float | None = None,
                     crest_length: float | None = None, base_depth: float | None = None,
                     min_joint_length: float = 0.05, joint_offset: float | None = None) -> Geometry:
    """The jointed slopes of cases.md A (seed 002): H = 15 m, face 45 deg, brick fabric.

    ``angle`` is ``"low"`` (persistent joints at 15 deg, inclined) or ``"high"`` (115 deg,
    anti-inclined). ``spacing`` is ``"fine"`` (s = 1 m, s:H = 1:15), ``"coarse"`` (s = 5 m, s:H
    = 1:3 as in the paper's text; its figure caption says 1:5, pass ``3.0`` for that) or a
    number [m]. Cross joints are perpendicular at d = 2 s, offset half a block between layers.

    ``joint_offset`` places the persistent joints relative to the toe, as a fraction of the
    spacing measured along the joints' normal: 0 puts one through the toe, 0.5 puts the toe
    midway between two. The paper's text fixes it only through its results: in the fine models
    "a critical persistent joint crosses the slope toe" (0), and the coarse result depends on
    whether "the next persistent joint does not cross the slope toe", the case it reports for
    its thick layers (0.5). Default: 0 for ``"fine"``, 0.5 for ``"coarse"`` and 0 for a number.

    Assumed (the paper gives no extents): toe floor 3 H, crest plateau 2 H, base H below the toe.
    """
    if angle not in FOUR_SLOPE_JOINT_DIP:
        raise ValueError(f"angle must be 'low' or 'high', got {angle!r}")
    s = FOUR_SLOPE_SPACING[spacing] if isinstance(spacing, str) else float(spacing)
    H = FOUR_SLOPE_HEIGHT
    toe_length = 3 * H if toe_length is None else toe_length
    base_depth = H if base_depth is None else base_depth
    slope = simple_slope(H, FOUR_SLOPE_FACE_ANGLE, crest_length=2 * H if crest_length is None else crest_length,
                         toe_length=toe_length, base_depth=base_depth, name="slope")
    # Layers start at the toe, so a persistent joint daylights through the toe as in the paper.
    toe = (toe_length, base_depth)
    dip = FOUR_SLOPE_JOINT_DIP[angle]
    n = (-math.sin(math.radians(dip)), math.cos(math.radians(dip)))
    if joint_offset is None:
        joint_offset = 0.5 if spacing == "coarse" else 0.0
    if not (math.isfinite(joint_offset) and 0.0 <= joint_offset < 1.0):
        raise ValueError(f"joint_offset must be a fraction of the spacing in [0, 1), got {joint_offset!r}")
    offset = toe[0] * n[0] + toe[1] * n[1] + joint_offset * s
    fabric = BrickSet(dip=dip, spacing=s, offset=offset, name=f"{angle}-angle brick fabric")
    return Geometry([slope], [fabric], min_joint_length=min_joint_length)


MULIASHI_SPACING_RULES = ("pitch", "gap")


def muliashi_model(spacing_rule: str = "pitch", above_toe: bool = True, min_joint_length: float = 0.05) -> Geometry:
    """The Muliashi open-pit slope of cases.md B (seed 001): 30 m x 22.5 m, 15 m bench at 65 deg,
    the model ending 7.5 m into the crest plateau; five layers of intermittent bedding joints,
    each joint 3 m long dipping 25 deg, layers 2.14 m apart (perpendicular).

    The paper's "horizontal distance of each joint in the same layer is 3 m" reads two ways:

    * ``spacing_rule="pitch"``: 3 m horizontally from the start of one joint to the start of the
      next, an along-trace period of ``3 / cos 25 = 3.31 m`` and rock bridges of 0.31 m
      (nearly persistent layers);
    * ``spacing_rule="gap"``: a 3 m horizontal gap between one joint's end and the next
      one's start, a period of ``(3 cos 25 + 3) / cos 25 = 6.31 m`` and rock bridges of 3.31 m.

    ``above_toe=True`` (the paper) keeps only the joints that lie wholly above the toe's
    elevation; ``False`` keeps every joint of the five layers, the floor and the ground below
    the toe included. Assumed: the lowest layer half a layer spacing above the bedding plane
    through the toe; joints of a layer start at whole periods from the point of the layer
    nearest the toe (the paper gives no phase).
    """
    if spacing_rule not in MULIASHI_SPACING_RULES:
        raise ValueError(f"spacing_rule must be one of {MULIASHI_SPACING_RULES}, got {spacing_rule!r}")
    width, height, bench, face = 30.0, 22.5, 15.0, 65.0
    crest = 7.5
    run = bench / math.tan(math.radians(face))
    toe_x = width - crest - run
    toe_y = height - bench
    slope = simple_slope(bench, face, crest_length=crest, toe_length=toe_x, base_depth=toe_y, name="slope")
    dip = math.radians(25.0)
    t = np.array([math.cos(dip), math.sin(dip)])
    n = np.array([-t[1], t[0]])
    trace, layer = 3.0, 2.14
    period = 3.0 / t[0] if spacing_rule == "pitch" else (3.0 * t[0] + 3.0) / t[0]
    toe = np.array([toe_x, toe_y])
    segments = []
    reach = math.hypot(width, height)
    for row in range(5):
        origin = toe + (row + 0.5) * layer * n
        for k in range(-int(reach / period) - 2, int(reach / period) + 2):
            a = origin + k * period * t
            b = a + trace * t
            if above_toe and min(a[1], b[1]) < toe_y:
                continue
            if max(a[0], b[0]) < 0 or min(a[0], b[0]) > width or max(a[1], b[1]) < 0 or min(a[1], b[1]) > height:
                continue
            if not slope.contains(np.array([a, b, 0.5 * (a + b)])).any():
                continue
            segments.append([a[0], a[1], b[0], b[1]])
    joints = SegmentSet(np.array(segments), name=f"bedding ({spacing_rule})")
    return Geometry([slope], [joints], min_joint_length=min_joint_length)


def block_on_incline_model(block_width: float = 1.0, block_height: float = 1.0, base_length: float = 10.0,
                           base_thickness: float = 1.0) -> Geometry:
    """A block resting on a plane, built horizontal (tilt gravity to incline it).

    Two bodies, ``incline`` (0) and ``block`` (1), meshed separately so they interact by contact.
    """
    base = rectangle(0.0, 0.0, base_length, base_thickness, name="incline")
    x0 = 0.5 * (base_length - block_width)
    block = rectangle(x0, base_thickness, block_width, block_height, name="block")
    return Geometry([base, block])


def planar_slope_model(height: float, face_angle: float, plane_angle: float, crest_length: float | None = None,
                       toe_length: float | None = None, base_depth: float | None = None,
                       tension_crack_offset: float | None = None, toe_step: float | None = None) -> Geometry:
    """A slope with one persistent joint daylighting in the face: the planar-failure verification
    problem (Hoek & Bray 1981, ch. 7; Wyllie & Mah 2004, ch. 6; :mod:`fdem.limit_equilibrium`).

    ``height`` H [m] is the face above the daylight point ``D`` of the plane, ``face_angle``
    psi_f and ``plane_angle`` psi_p [deg] (``psi_p < psi_f``). Joint set 1 is the sliding plane,
    from ``D`` up at psi_p to the horizontal upper surface, or, with ``tension_crack_offset`` b
    [m], to the foot of a vertical tension crack b behind the crest: joint set 2, of depth
    ``z = H - (H cot psi_f + b) tan psi_p``.

    ``toe_step`` [m] (default ``H/5``) continues the face below ``D`` down to the toe floor. The
    down-dip direction from ``D`` points into air only there: with the plane daylighting at the
    very toe of a horizontal floor (``toe_step=0``) the block's tip is driven into the floor
    rock, which then holds the block over a finite slip; limit equilibrium assumes it free to
    slide out.

    Assumed extents, compact since the block's equilibrium does not depend on them: toe floor
    ``toe_length`` (default 0.3 H) left of the toe, base ``base_depth`` (default 0.3 H) below
    it, and a crest plateau reaching ``crest_length`` (default H/2 beyond the point where the
    plane or the crack meets the upper surface) behind the crest. ``D`` lies at
    ``(toe_length + toe_step cot psi_f, base_depth + toe_step)``.
    """
    H, pf, pp = float(height), float(face_angle), float(plane_angle)
    if not H > 0:
        raise ValueError(f"planar slope: height must be positive, got {height} m")
    if not 0 < pp < pf <= 90:
        raise ValueError(f"planar slope: need 0 < plane angle < face angle <= 90 deg for the plane to daylight "
                         f"in the face, got plane {plane_angle} deg, face {face_angle} deg")
    step = 0.2 * H if toe_step is None else float(toe_step)
    if step < 0:
        raise ValueError(f"planar slope: toe_step must be >= 0, got {toe_step} m")
    cot_f = 0.0 if pf == 90 else 1.0 / math.tan(math.radians(pf))
    cot_p, tan_p = 1.0 / math.tan(math.radians(pp)), math.tan(math.radians(pp))
    run_above = H * cot_f                      # face run from D to the crest
    if tension_crack_offset is None:
        reach = H * cot_p                      # plane meets the upper surface this far from D
    else:
        b = float(tension_crack_offset)
        reach = run_above + b
        if b <= 0 or reach * tan_p >= H:
            raise ValueError(f"planar slope: the tension crack must stand behind the crest (b > 0) and reach the "
                             f"plane below the surface (b < {H * cot_p - run_above:.6g} m), got b = {b} m")
    toe_length = 0.3 * H if toe_length is None else float(toe_length)
    base_depth = 0.3 * H if base_depth is None else float(base_depth)
    crest_length = (reach - run_above) + 0.5 * H if crest_length is None else float(crest_length)
    if crest_length <= reach - run_above:
        raise ValueError(f"planar slope: crest_length {crest_length} m must exceed "
                         f"{reach - run_above:.6g} m, where the joints meet the upper surface")
    if step > 0:
        slope = simple_slope(H + step, pf, crest_length=crest_length, toe_length=toe_length,
                             base_depth=base_depth, name="slope")
        dx, dy = toe_length + step * cot_f, base_depth + step
    else:
        slope = simple_slope(H, pf, crest_length=crest_length, toe_length=toe_length, base_depth=base_depth,
                             name="slope")
        dx, dy = toe_length, base_depth
    end = (dx + reach, dy + reach * tan_p)
    sets = [SegmentSet([[dx, dy, end[0], end[1]]], name="sliding plane")]
    if tension_crack_offset is not None:
        sets.append(SegmentSet([[end[0], end[1], end[0], dy + H]], name="tension crack"))
    return Geometry([slope], sets)
