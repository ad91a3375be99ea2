"""Brazilian disc (verification.md): the peak platen load recovers the crack elements' tensile
strength within 15 %, and the first crack opens near the centre on the loaded diameter."""
import importlib.util
from pathlib import Path

import pytest

CASE = Path(__file__).resolve().parents[1] / "cases" / "brazilian_disc.py"


@pytest.fixture(scope="module")
def brazilian():
    spec = importlib.util.spec_from_file_location("brazilian_disc", CASE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.run(divisions=25)


def test_peak_load_recovers_tensile_strength(brazilian):
    # sigma_t = 2 P_max / (pi D t)
    assert brazilian["ratio"] == pytest.approx(1.0, abs=0.15)


def test_first_crack_is_tensile_near_the_centre_on_the_loaded_diameter(brazilian):
    first = brazilian["first_event"]
    assert first["mode"] == "I"
    assert first["distance_from_centre_over_R"] < 0.4
    assert abs(first["x"]) < 0.05 * 0.05  # within 5 % of R of the vertical diameter


def test_disc_mesh_follows_the_requested_size():
    """The triangle count grows as (D / h)^2: the disc polygon's sides follow the element size
    (with a fixed 96-gon, D/15 and D/25, and D/40 and D/60, gave the same meshes)."""
    from fdem.cases.brazilian_disc import disc_mesh

    counts = {d: len(disc_mesh(d).triangles) for d in (15, 25, 40, 60)}
    for a, b in ((15, 25), (25, 40), (40, 60)):
        assert counts[b] / counts[a] == pytest.approx((b / a) ** 2, rel=0.25)
