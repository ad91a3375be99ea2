"""How much the friction law of contact pairs matters in a slope's debris: the touching pairs of
a saved state, with the friction each law gives them.

Until 2026-11-25 a pair not across a broken crack element took the lowest friction of all six
faces of its two triangles; it now takes the lower friction of the two faces in touch
(:func:`fdem.kernels.contact_pairs.pair_friction`). A debris triangle with one face on a broken
joint (phi = 11 deg in the four slopes) then slid on the floor at 11 deg with any of its faces.
This script reads a checkpoint (``final_state.npz``: the debris at rest), rebuilds the faces'
friction from the broken elements it holds, and for every touching pair compares the two laws,
weighting by the pair's normal force:

    python cases/benchmarks/face_friction_check.py runs/rest2/low_fine_1.0_crest60_toe90 --scene low_fine

It prints and returns the share of touching pairs (and of the normal force they carry) whose
friction is higher by face than by triangle, and the force-weighted mean friction angles.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from fdem.kernels import contact_pairs as kc
from fdem.mesh.mesh import Mesh
from fdem.mesh.topology import build_topology
from fdem.physics.contact import ContactSet, pair_energy_force
from fdem.solve.checkpoint import read_checkpoint


def compare(run: Path, scene: str, state: str = "final_state.npz", friction_angle: float = 30.0) -> dict:
    """The two laws over the touching pairs of ``run/state`` (mesh ``run/<scene>.npz``; the
    contact set's face friction ``friction_angle`` [deg], the four slopes' 30)."""
    saved = read_checkpoint(run / state)
    topo = build_topology(Mesh.load(run / f"{scene}.npz"))
    contact_state = next(p for p in saved["state"]["providers"] if p.get("kind") == "ContactSet")
    x = np.asarray(saved["state"]["x"])
    contact = ContactSet(topo, 1.0, friction_angle=friction_angle, check_overlap=False)
    broken = np.flatnonzero(contact_state["broken"])
    contact.activate_cracks(broken, mu=np.asarray(contact_state["crack_mu"])[broken])
    faces = contact.face_friction
    lowest = faces.min(axis=1)  # the earlier law: a triangle's lowest face
    pairs, mu_pair = contact_state["pairs"], contact_state["pair_mu_base_pair"]
    across = ~np.isclose(mu_pair, np.minimum(lowest[pairs[:, 0]], lowest[pairs[:, 1]]))  # a broken element's own
    old, new, force = [], [], []
    for q in np.flatnonzero(contact_state["pair_touching"]):
        i, j = (int(t) for t in pairs[q])
        ci, cj = x[3 * i:3 * i + 3], x[3 * j:3 * j + 3]
        _, f_i, _, area = pair_energy_force(ci, cj, 1.0)
        fn = float(np.linalg.norm(f_i.sum(axis=0)))
        if not (area > 0 and fn > 0):
            continue
        n = f_i.sum(axis=0) / fn
        by_triangle = float(mu_pair[q]) if across[q] else min(lowest[i], lowest[j])
        by_face = float(mu_pair[q]) if across[q] else kc.pair_friction(kc.FROM_FACES, faces, i, j, *ci.ravel(),
                                                                         *cj.ravel(), n[0], n[1])
        old.append(by_triangle)
        new.append(by_face)
        force.append(fn)
    old, new, force = np.array(old), np.array(new), np.array(force)
    higher = new > old + 1e-12
    deg = lambda m: math.degrees(math.atan(m))  # noqa: E731
    return {"run": str(run), "touching_pairs": int(len(force)), "broken_elements": int(broken.size),
            "share_higher_by_face": float(higher.mean()), "force_share_higher_by_face": float(force[higher].sum() / force.sum()),
            "mean_friction_deg_by_triangle": deg(float(np.average(old, weights=force))),
            "mean_friction_deg_by_face": deg(float(np.average(new, weights=force)))}


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--scene", required=True, help="the mesh's name in the run folder (low_fine, high_coarse, ...)")
    parser.add_argument("--state", default="final_state.npz")
    args = parser.parse_args(argv)
    result = compare(args.run, args.scene, args.state)
    print(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
