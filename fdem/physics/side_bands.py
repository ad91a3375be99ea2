"""Elastic side bands: crack elements along the left and right boundaries that never yield.

A slope model ends at rollers, and the rock beyond them is not in the model. Where a jointed
rock mass meets a roller, the slabs its joints cut off are held only horizontally, and slip or
breakage there belongs to the boundary, not to the slope (``docs/cases.md`` A, "Boundaries").
Joints are kept out of bands along the sides by the geometry
(:class:`fdem.geometry.joint_sets.BandedSet`); the intact rock of such a band still softens and
breaks under strength reduction. An *elastic* band goes one step further: its intact crack
elements get the rock's penalties (so the band is exactly as stiff as the rock beside it: the
static start does not change) and strengths that no stress in a slope reaches, so the band is
a far field that carries the rollers' load and cannot join the mechanism. Comparing the factor
of safety with rock bands and with elastic ones shows whether the boundary takes part.

The crack set gets the band's elements under a tag of their own (one past the largest tag of
its property sets, its ``tags``); the topology the model and the outputs read keeps the
geometry's tags, so pictures and summaries count the bands as intact rock.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from fdem.mesh.topology import INTACT
from fdem.physics.crack_properties import CrackProperties

__all__ = ["ELASTIC_STRENGTH", "ELASTIC_FRACTURE_ENERGY", "stays_elastic", "can_break", "side_band_mask",
           "with_elastic_side_bands"]


ELASTIC_STRENGTH = 1e12
"""Tensile strength and cohesion [Pa] of a crack element that stays elastic: some 1e5 times the
stress at the base of a kilometre of rock, so that no reduction factor a slope is taken to (the
strengths divided by F >= 1e-3) brings it within reach."""


ELASTIC_FRACTURE_ENERGY = 1e24
"""Fracture energies [J/m^2] of such an element, large enough that its softening branch stays
longer than its elastic one (:class:`CrackProperties` refuses snap-back, ``G_I > f_t^2 L0 /
(2 p_n)`` with the reduced ``f_t / F``) for any element up to 1 km long, any normal penalty above
1e6 Pa and F >= 1e-3: ``2 G p_n F^2 / (f_t^2 L0) >= 2``. Nothing overflows: the opening that
softens it fully, about ``2 G / f_t``, is 2e12 m."""


def stays_elastic(props: CrackProperties, name: str | None = None) -> CrackProperties:
    """``props`` with its penalties and friction angle kept and strengths no stress reaches:
    ``f_t = c =`` :data:`ELASTIC_STRENGTH`, ``G_I = G_II =`` :data:`ELASTIC_FRACTURE_ENERGY`."""
    return dataclasses.replace(props, f_t=ELASTIC_STRENGTH, c=ELASTIC_STRENGTH, G_I=ELASTIC_FRACTURE_ENERGY,
                               G_II=ELASTIC_FRACTURE_ENERGY, name=name if name is not None else props.name)


def can_break(props: CrackProperties) -> bool:
    """False for a set made by :func:`stays_elastic` (its strength no stress reaches): such a set
    takes no part in figures drawn from the breakable sets (the events' stress drop)."""
    return props.f_t < ELASTIC_STRENGTH


def side_band_mask(topology, band: float) -> np.ndarray:
    """(n_cracks,) bool: the crack elements whose reference midpoint lies within ``band`` [m] of
    the model's left or right side (its smallest or largest node x)."""
    if not (isinstance(band, (int, float, np.floating)) and not isinstance(band, bool) and math.isfinite(band)
            and band > 0):
        raise ValueError(f"an elastic side band needs a positive finite width [m], got {band!r}")
    x0 = np.asarray(topology.x0, float)
    mid_x = x0[np.asarray(topology.crack_nodes)[:, :2], 0].mean(axis=1)
    return (mid_x < x0[:, 0].min() + band) | (mid_x > x0[:, 0].max() - band)


def with_elastic_side_bands(topology, sets: dict[int, CrackProperties], band: float):
    """``(tags, sets, tag)`` for a crack set with elastic side bands ``band`` [m] wide.

    The intact elements (tag 0) of :func:`side_band_mask` move to ``tag`` (one past the largest
    key of ``sets``), whose set is :func:`stays_elastic` of the intact rock's; ``tags`` is the
    topology's ``crack_tag`` with those moved, for ``CrackSet(topology, sets, tags=tags)`` (the
    topology keeps the geometry's tags, which the outputs read). Joint elements inside a band
    keep their tags: keep the joints out of the bands in the geometry."""
    if INTACT not in sets:
        raise ValueError("elastic side bands copy the intact rock's crack properties: the sets have no tag 0")
    tag = max(sets) + 1
    tags = np.asarray(topology.crack_tag, dtype=np.int32).copy()
    inside = side_band_mask(topology, band) & (tags == INTACT)
    if not inside.any():
        length = float(np.median(np.asarray(topology.crack_length0, float)))
        raise ValueError(f"elastic side bands {band:g} m wide hold no intact crack element (the elements are "
                         f"about {length:.3g} m long): make them at least one element wide")
    tags[inside] = tag
    sets = {**sets, tag: stays_elastic(sets[INTACT], name=f"{sets[INTACT].name or 'intact rock'} (elastic side bands)")}
    return tags, sets, tag
