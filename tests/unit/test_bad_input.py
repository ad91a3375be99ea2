"""Bad input is refused where it is given, with a message that names the parameter, the value
and the place (design.md sec. 6), and coinciding joint sets are reported, not merged silently."""
import math
import warnings

import numpy as np
import pytest

from fdem.geometry.section import Geometry
from fdem.geometry.joint_sets import PersistentSet, SegmentSet
from fdem.geometry.polygons import rectangle
from fdem.geometry.dfn import CoincidentJointsWarning
from fdem.physics.elastic import ElasticMaterial
from fdem.mesh.mesh import structured_rectangle
from fdem.mesh.topology import ConformingTopology
from fdem.solve.model import Model

ROCK = dict(young=1e9, poisson=0.25, density=2700.0)


@pytest.fixture
def model():
    return Model(ConformingTopology.from_mesh(structured_rectangle(2, 2, 1.0, 1.0)), ElasticMaterial(**ROCK))


@pytest.mark.parametrize("name, value", [("young", math.nan), ("young", math.inf), ("poisson", math.nan),
                                         ("density", math.nan), ("density", -math.inf),
                                         ("viscosity", math.nan), ("viscosity", math.inf), ("viscosity", -1.0)])
def test_material_parameter_not_finite_or_negative(name, value):
    with pytest.raises(ValueError, match=rf"ElasticMaterial: {name} must be .*{value}"):
        ElasticMaterial(**{**ROCK, name: value})


def test_nan_viscosity_is_not_taken_as_zero():
    # NaN compared false with 0, so it used to pass as "no viscosity"
    with pytest.raises(ValueError, match="viscosity"):
        ElasticMaterial(**ROCK, viscosity=float("nan"))


@pytest.mark.parametrize("g", [(math.nan, -9.81), (0.0, math.inf)])
def test_gravity_not_finite(model, g):
    with pytest.raises(ValueError, match=r"set_gravity: gravity .*(nan|inf)"):
        model.set_gravity(*g)


def test_initial_stress_names_the_triangle(model):
    def stress(x, y):  # NaN in the triangles right of x = 0.5 only
        s = np.column_stack([-1e5 * np.ones_like(x), -2e5 * np.ones_like(x), np.zeros_like(x)])
        s[x > 0.5, 1] = np.nan
        return s

    first_bad = int(np.flatnonzero(model.centroids0[:, 0] > 0.5)[0])
    with pytest.raises(ValueError, match=rf"set_initial_stress: stress of triangle {first_bad} .*nan"):
        model.set_initial_stress(stress)
    assert not model.initial_stress.any()  # nothing half-written


def test_initial_stress_constant_not_finite(model):
    with pytest.raises(ValueError, match=r"stress of triangle 0 .*inf"):
        model.set_initial_stress([0.0, math.inf, 0.0])


@pytest.mark.parametrize("kw, label", [({"vx": math.nan}, "vx"), ({"vx": 0.0, "vy": -math.inf}, "vy")])
def test_prescribed_velocity_not_finite(model, kw, label):
    with pytest.raises(ValueError, match=rf"prescribe_velocity: {label} \(selection 'bottom'\) must be finite"):
        model.prescribe_velocity("bottom", **kw)


def test_velocity_history_not_finite_is_caught_with_time_and_value(model):
    model.prescribe_velocity("top", vy=-0.01, history=lambda t: 1.0 if t < 0.5 else float("nan"))
    v = np.zeros((model.n_nodes, 2))
    model.update_prescribed_velocity(v, 0.25)
    assert np.all(v[model.select_nodes("top"), 1] == -0.01)
    with pytest.raises(ValueError, match=r"history\(0\.75 s\) of the y velocity .* returned nan"):
        model.update_prescribed_velocity(v, 0.75)


def test_body_and_nodal_forces_not_finite(model):
    with pytest.raises(ValueError, match=r"add_body_force: body force \(bx, by\).*nan"):
        model.add_body_force(0.0, math.nan)
    with pytest.raises(ValueError, match=r"add_nodal_force: force \(fx, fy\).*inf"):
        model.add_nodal_force("top", math.inf, 0.0)
    assert not model.external_force.any()


@pytest.mark.parametrize("fraction", [-0.1, math.nan])
def test_element_damping_fraction(model, fraction):
    with pytest.raises(ValueError, match="set_element_damping: fraction"):
        model.set_element_damping(fraction)


def test_coinciding_joint_sets_are_reported_with_both_names_and_place():
    box = rectangle(0, 0, 10, 10)
    bedding = PersistentSet(dip=0.0, spacing=2.0, offset=1.0, name="bedding")   # y = 1, 3, 5, 7, 9
    fault = SegmentSet([[2.0, 5.0, 8.0, 5.0]], name="fault")                   # on the line y = 5
    with pytest.warns(CoincidentJointsWarning, match=r"joint sets 1 \('bedding'\) and 2 \('fault'\) coincide "
                                                     r"in body 0 .* from \(2, 5\) to \(8, 5\) m"):
        dfn = Geometry([box], [bedding, fault]).dfn()
    assert set(dfn.set_id.tolist()) == {1}  # the overlap is one joint of the lower-numbered set


def test_one_set_merges_its_own_collinear_joints_without_warning():
    box = rectangle(0, 0, 10, 10)
    own = SegmentSet([[1.0, 5.0, 6.0, 5.0], [4.0, 5.0, 9.0, 5.0]], name="own")   # overlap within one set
    other = SegmentSet([[5.0, 1.0, 5.0, 4.0]], name="other")                      # not on that line
    with warnings.catch_warnings():
        warnings.simplefilter("error", CoincidentJointsWarning)
        dfn = Geometry([box], [own, other]).dfn()
    horizontal = dfn.segments[dfn.set_id == 1]
    assert np.linalg.norm(horizontal[:, 1] - horizontal[:, 0], axis=1).sum() == pytest.approx(8.0)
