"""What picking the faces in touch costs the contact pair loop, on a slope's debris.

Since 2026-11-25 a pair not across a broken crack element takes its friction from the two faces
in touch, picked every step by the contact normal (:func:`fdem.kernels.contact_pairs.pair_friction`).
This script times :func:`fdem.kernels.contact_pairs.pair_forces` on the pairs of a saved state
(``final_state.npz`` of a run to rest: debris with broken faces of two frictions) three ways,
interleaved, each the best of ``--repeats`` rounds:

* ``faces``: the law as it runs (faces of different friction picked by the normal);
* ``uniform faces``: every face one friction, so that no face is picked (the same loop otherwise);
* ``per-pair constant``: every pair given its own coefficient, the loop of before the change
  (one array read per pair).

    NUMBA_NUM_THREADS=1 python cases/benchmarks/bench_face_friction.py runs/rest2/low_fine_1.0_crest60_toe90 --scene low_fine

Prints and saves ``docs/benchmarks/face_friction.json``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from records import record, save  # noqa: E402

from fdem.cases.four_slopes import CONTACT_PENALTY  # noqa: E402
from fdem.kernels import contact_pairs as kc  # noqa: E402
from fdem.mesh.mesh import Mesh  # noqa: E402
from fdem.mesh.topology import build_topology  # noqa: E402
from fdem.physics.contact import ContactSet  # noqa: E402
from fdem.solve.checkpoint import read_checkpoint  # noqa: E402


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--scene", required=True)
    parser.add_argument("--state", default="final_state.npz")
    parser.add_argument("--calls", type=int, default=200, help="pair-loop calls per round")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args(argv)
    saved = read_checkpoint(args.run / args.state)
    topo = build_topology(Mesh.load(args.run / f"{args.scene}.npz"))
    st = saved["state"]
    cs = next(p for p in st["providers"] if p.get("kind") == "ContactSet")
    contact = ContactSet(topo, 1.0, friction_angle=30.0, check_overlap=False)
    broken = np.flatnonzero(cs["broken"])
    contact.activate_cracks(broken, mu=np.asarray(cs["crack_mu"])[broken])
    x, v = np.ascontiguousarray(st["x"]), np.ascontiguousarray(st["v"])
    pairs = np.asarray(cs["pairs"], np.int64)
    pi, pj = np.ascontiguousarray(pairs[:, 0]), np.ascontiguousarray(pairs[:, 1])
    bounds = kc.chunk_bounds(pi, min(1024, max(1, len(pi) // 128)))
    mu_base, kt, damp = kc.pair_constants(pi, pj, topo.n_triangles, contact._crack_keys, contact._crack_order,
                                          contact._broken, contact._crack_mu, True, contact._kt_tri, np.zeros(0), 0.0)
    faces = contact.face_friction
    uniform = np.full_like(faces, float(faces.max()))
    per_pair = np.where(mu_base >= 0.0, mu_base, float(faces.min()))
    penalty = CONTACT_PENALTY  # the four slopes' (the cost does not depend on it)
    variants = {"faces": (mu_base, faces), "uniform faces": (mu_base, uniform), "per-pair constant": (per_pair, faces)}
    best = {k: np.inf for k in variants}
    n_touch = None
    for _ in range(args.repeats):
        for name, (mb, fm) in variants.items():
            hist = np.asarray(cs["pair_history"], np.float64).copy()
            touching = np.asarray(cs["pair_touching"], np.uint8).copy()
            witness = np.zeros(len(pi), np.uint8)
            f_t = np.zeros((len(pi), 6))
            f = np.zeros_like(x)
            kc.pair_forces(x, v, pi, pj, bounds, penalty, mb, fm, 1.0, kt, damp, 1e-5, hist, f_t, touching, witness, f)
            t0 = time.perf_counter()
            for _ in range(args.calls):
                kc.pair_forces(x, v, pi, pj, bounds, penalty, mb, fm, 1.0, kt, damp, 1e-5, hist, f_t, touching,
                               witness, f)
            best[name] = min(best[name], (time.perf_counter() - t0) / args.calls)
            n_touch = int(touching.sum())
    threads = int(os.environ.get("NUMBA_NUM_THREADS", os.cpu_count() or 1))
    for name, t in best.items():
        print(f"{name}: {1e3 * t:.3f} ms per call ({len(pi)} pairs, {n_touch} touching)")
    overhead = best["faces"] / best["per-pair constant"] - 1.0
    print(f"picking the faces costs {100 * overhead:+.1f} % of the pair loop against a per-pair constant")
    records = [record(f"contact pair loop, {name}", 1e3 * t, "ms/call", topo.n_triangles, threads)
               for name, t in best.items()]
    save("face_friction", records, run=str(args.run), n_pairs=int(len(pi)), n_touching=n_touch,
         overhead=overhead, load=os.getloadavg()[0])
    return {"best_s": best, "overhead": overhead}


if __name__ == "__main__":
    main()
