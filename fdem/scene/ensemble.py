"""A scene file as the unit an ensemble varies: ``fdem run ensemble --scene my_slope.toml``.

The scene's ``[ensemble]`` table says how many realizations, how they are sampled and which
keys vary, each a dotted path into the scene with a distribution::

    [ensemble]
    n = 20
    seed = 0
    method = "lhs"                    # Latin hypercube, or "mc"
    fos = [0.8, 2.0, 0.05]            # the factor-of-safety bracket of every realization

    [ensemble.vary]
    "cracks.1.c" = ["lognormal", 2e4, 5e3]            # mean, sd [Pa]
    "cracks.1.phi" = ["normal", 28.0, 3.0, 20.0, 36.0] # mean, sd, truncated to [low, high]
    "joints.1.through_toe" = ["uniform", 0.0, 0.9]
    "heterogeneity.seed" = ["seed"]                   # an integer seed per realization

Paths: ``section.key``; ``cracks.TAG.key``; ``joints.J.key`` and ``monitors.J.key`` with ``J``
counted from 1, as the tables appear. Only numeric keys vary (a seed key takes ``["seed"]``).
Distributions are :class:`fdem.workflow.ensembles.Distribution`: ``["fixed", v]``,
``["uniform", lo, hi]``, ``["normal", mean, sd]`` or ``["normal", mean, sd, lo, hi]``,
``["lognormal", mean, sd]``, ``["seed"]``. Every path and distribution is checked when the
ensemble is built; a sampled value the scene refuses (outside a key's range) makes that
realization an error row with the message, not the end of the ensemble.
"""
from __future__ import annotations

import copy
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from fdem.scene.schema import ARRAYS, BY_TAG, SCHEMA, SceneError, check_scene

__all__ = ["ENSEMBLE_KEYS", "SceneRealization", "Realized", "vary_parameters", "scene_ensemble"]

ENSEMBLE_KEYS = {"n": 20, "seed": 0, "method": "lhs", "fos": [0.5, 3.0, 0.02], "runout": False, "vary": None}
"""Keys of a scene's ``[ensemble]`` table and their defaults (``runout``: run the scene's
workflow after the factor-of-safety search and record the runout)."""

_ARITY = {"fixed": (1,), "uniform": (2,), "normal": (2, 4), "lognormal": (2,), "seed": (0,)}


@dataclass(frozen=True)
class Realized:
    """What a realization's scene returns to the ensemble: the simulation in equilibrium and
    the toe abscissa [m] for the runout."""

    sim: object
    toe_x: float


@dataclass(frozen=True)
class SceneRealization:
    """The ensemble's scene callable (picklable: the scene travels as its TOML text).

    ``text``: the scene file's text; ``paths``: ``(parameter name, dotted path)`` pairs; ``name``:
    the file's name, for messages. ``SceneRealization(...)(**parameters)`` sets each path to its
    sampled value, checks the scene, meshes it and returns :class:`Realized`."""

    text: str
    paths: tuple[tuple[str, str], ...]
    name: str = "scene.toml"

    def scene(self, **parameters) -> dict:
        """The checked scene with ``parameters`` set at their paths."""
        raw = tomllib.loads(self.text)
        raw.pop("ensemble", None)
        by_name = dict(self.paths)
        for name, value in parameters.items():
            _set(raw, by_name[name], value)
        return check_scene(raw, Path(self.name))

    def __call__(self, **parameters) -> Realized:
        import warnings

        from fdem.mesh.topology import build_topology
        from fdem.scene.build import build_simulation, scene_mesh, scene_toe

        s = self.scene(**parameters)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # dropped short joint pieces are expected in a varied DFN
            geo, mesh = scene_mesh(s)
        sim, _, _ = build_simulation(s, build_topology(mesh), None, pictures=False, progress=False, where=self.name)
        return Realized(sim, scene_toe(s, geo)[0])


def _set(raw: dict, path: str, value) -> None:
    section, *rest = path.split(".")
    if section in ARRAYS:
        table = raw[section][int(rest[0]) - 1]
    elif section in BY_TAG:
        table = raw[section][rest[0]]
    else:
        table = raw.setdefault(section, {})
    key = rest[-1]
    kind = SCHEMA[section][key].kind
    table[key] = int(value) if kind == "int" else float(value)


def _check_path(raw: dict, path: str, where: str) -> str:
    """The kind (``float``/``int``) of the key at ``path``, or a :class:`SceneError`."""
    parts = path.split(".")
    section = parts[0]
    if section not in SCHEMA or section == "ensemble":
        raise SceneError(f"{where}: [ensemble.vary] {path!r}: no section [{section}]")
    if section in ARRAYS or section in BY_TAG:
        if len(parts) != 3:
            what = "TAG" if section in BY_TAG else "J (from 1)"
            raise SceneError(f"{where}: [ensemble.vary] {path!r}: write {section}.{what}.key")
        if section in ARRAYS:
            tables = raw.get(section, [])
            if not (parts[1].isdigit() and 1 <= int(parts[1]) <= len(tables)):
                raise SceneError(f"{where}: [ensemble.vary] {path!r}: the scene has {len(tables)} [[{section}]] "
                                 "table(s), counted from 1")
        elif parts[1] not in raw.get(section, {}):
            raise SceneError(f"{where}: [ensemble.vary] {path!r}: the scene has no [{section}.{parts[1]}]")
    elif len(parts) != 2:
        raise SceneError(f"{where}: [ensemble.vary] {path!r}: write {section}.key")
    key = parts[-1]
    if key not in SCHEMA[section]:
        raise SceneError(f"{where}: [ensemble.vary] {path!r}: [{section}] has no key {key!r}")
    kind = SCHEMA[section][key].kind
    if kind not in ("float", "int"):
        raise SceneError(f"{where}: [ensemble.vary] {path!r}: only numeric keys vary, {key} is {kind}")
    return kind


def _distribution(spec, path: str, kind: str, where: str):
    from fdem.workflow.ensembles import Distribution

    forms = '["fixed", v], ["uniform", lo, hi], ["normal", mean, sd(, lo, hi)], ["lognormal", mean, sd], ["seed"]'
    if not (isinstance(spec, list) and spec and spec[0] in _ARITY and len(spec) - 1 in _ARITY[spec[0]]
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in spec[1:])):
        raise SceneError(f"{where}: [ensemble.vary] {path!r} = {spec!r}: must be one of {forms}")
    if kind == "int" and spec[0] not in ("seed", "fixed"):
        raise SceneError(f"{where}: [ensemble.vary] {path!r}: a whole-number key takes [\"seed\"] or [\"fixed\", v]")
    if spec[0] == "seed" and kind != "int":
        raise SceneError(f"{where}: [ensemble.vary] {path!r}: [\"seed\"] is for whole-number keys (a seed)")
    try:
        dist = getattr(Distribution, spec[0])(*spec[1:])
        dist.check(path)
    except ValueError as err:
        raise SceneError(f"{where}: [ensemble.vary] {path!r}: {err}") from None
    return dist


def vary_parameters(raw: dict, where: str) -> tuple[dict, tuple[tuple[str, str], ...]]:
    """``({parameter name: Distribution}, ((name, path), ...))`` of a raw scene's
    ``[ensemble.vary]``; names are the paths with every non-word character made ``_``."""
    vary = (raw.get("ensemble") or {}).get("vary") or {}
    if not isinstance(vary, dict) or not vary:
        raise SceneError(f"{where}: an ensemble needs [ensemble.vary] with at least one key, e.g. "
                         '"cracks.1.c" = ["lognormal", 2e4, 5e3]')
    dists, paths = {}, []
    for path, spec in vary.items():
        kind = _check_path(raw, path, where)
        name = re.sub(r"\W", "_", path)
        dists[name] = _distribution(spec, path, kind, where)
        paths.append((name, path))
    return dists, tuple(paths)


def scene_ensemble(path: str | Path, n: int | None = None, seed: int | None = None, method: str | None = None,
                   max_time: float | None = None, pictures: bool = True):
    """The :class:`fdem.workflow.ensembles.Ensemble` of the scene file ``path`` and its
    ``[ensemble]`` table (``n``, ``seed``, ``method`` given here override the table's). The
    scene itself is checked whole first, and one realization at the distributions' medians is
    checked too (a varied key whose whole range the scene refuses is found now)."""
    from fdem.workflow.ensembles import Ensemble

    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: no such scene file")
    text = path.read_text()
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"{path}: not valid TOML: {err}") from None
    table = raw.get("ensemble")
    if not isinstance(table, dict):
        raise SceneError(f"{path}: an ensemble scene needs an [ensemble] table (docs/scenes.md, Ensembles)")
    unknown = sorted(set(table) - set(ENSEMBLE_KEYS))
    if unknown:
        raise SceneError(f"{path}: [ensemble]: unknown key(s) {', '.join(unknown)}; the keys are: "
                         f"{', '.join(ENSEMBLE_KEYS)}")
    settings = {**ENSEMBLE_KEYS, **table}
    plain = copy.deepcopy(raw)
    plain.pop("ensemble")
    scene = check_scene(plain, path)
    dists, paths = vary_parameters(raw, str(path))
    realization = SceneRealization(text, paths, path.name)
    medians = {k: (d.a if d.kind == "fixed" else 0 if d.kind == "seed" else float(d.ppf(0.5)))
               for k, d in dists.items()}
    try:
        realization.scene(**medians)
    except SceneError as err:
        raise SceneError(f"{path}: [ensemble.vary] at the distributions' medians: {err}") from None
    fos = settings["fos"]
    if not (isinstance(fos, list) and len(fos) == 3):
        raise SceneError(f"{path}: [ensemble] fos must be [lower, upper, tolerance], got {fos!r}")
    from fdem.scene.objects import workflow

    search = workflow(scene)   # each realization's search is judged by the scene's trial rule
    runout = None
    if settings["runout"]:
        runout = search
        if runout.reduction == "none":
            raise SceneError(f"{path}: [ensemble] runout = true runs each realization's workflow after its search, "
                             f"and [workflow] reduction = \"none\" has none: set reduction to steps or rate, or "
                             f"runout = false")
    try:
        return Ensemble(realization, dists, n=settings["n"] if n is None else n,
                        seed=settings["seed"] if seed is None else seed,
                        method=settings["method"] if method is None else method, fos=tuple(fos), runout=runout,
                        pictures=pictures, max_time=max_time, search=search)
    except ValueError as err:
        raise SceneError(f"{path}: [ensemble]: {err}") from None
