"""Brazilian disc (verification.md): the peak platen load recovers the crack elements' tensile
strength within 15 % when the disc is large against the process zone, and the first crack opens
near the centre on the loaded diameter."""
import pytest

from conftest import load_case


@pytest.fixture(scope="module")
def brazilian():
    module = load_case("brazilian_disc")
    # The elastic formula holds for a brittle disc, D >> l_pz = E G_I / f_t^2: D = 50 l_pz here
    # (G_I = 5 J/m^2). At the case's G_I = 20 (D = 12.5 l_pz) the size effect alone puts the model's
    # strength at 1.15 f_t, the mean over load directions, converged in h (docs/pareto.md).
    return module.run(divisions=25, fracture_energy=5.0)


def test_peak_load_recovers_tensile_strength(brazilian):
    # sigma_t = 2 P_max / (pi D t)
    assert brazilian["ratio"] == pytest.approx(1.0, abs=0.15)


def test_first_crack_is_tensile_on_the_loaded_diameter_clear_of_the_platens(brazilian):
    """Along the loaded diameter sigma_xx = 2 P / (pi D t) is uniform (Hertz), so a tension
    cut-off does not single out the centre: the first element to break is the best-aligned one
    on the diameter (0.05 R on the earlier, wrongly sized mesh; 0.30 R at G_I = 20 and 0.54 R at
    G_I = 5 on the corrected one). It must open in mode I, on the diameter, clear of the zones
    under the platens where the loading arcs lower sigma_xx."""
    first = brazilian["first_event"]
    assert first["mode"] == "I"
    assert first["distance_from_centre_over_R"] < 0.6
    assert abs(first["x"]) < 0.05 * 0.05  # within 5 % of R of the vertical diameter


def test_disc_mesh_follows_the_requested_size():
    """The triangle count grows as (D / h)^2: the disc polygon's sides follow the element size
    (with a fixed 96-gon, D/15 and D/25, and D/40 and D/60, gave the same meshes)."""
    from fdem.cases.brazilian_disc import disc_mesh

    counts = {d: len(disc_mesh(d).triangles) for d in (15, 25, 40, 60)}
    for a, b in ((15, 25), (25, 40), (40, 60)):
        assert counts[b] / counts[a] == pytest.approx((b / a) ** 2, rel=0.25)
