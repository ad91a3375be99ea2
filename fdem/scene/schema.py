"""The scene file's keys, their types, units and ranges, and :func:`read_scene` that checks a file
against them before any work.

A scene file (TOML, read with the standard library's ``tomllib``) describes one slope: its
outline or its own Gmsh mesh, joint sets, rock, crack-element property sets by tag, contact,
supports, gravity, heterogeneity, the workflow and the outputs (``docs/scenes.md`` walks through
one). Every key is declared here once (:data:`SCHEMA`), with its type, unit, allowed range and
default; :func:`check_scene` refuses, before meshing, an unknown section or key (a typo would
otherwise be ignored for hours), a missing required key, a value of the wrong type or outside
its range, and every message names the file, the section and the key::

    my_slope.toml: [rock] young = -5e9: must be > 0 (Young's modulus [Pa])

The checked scene is a plain ``dict`` of sections, defaults filled in; :mod:`fdem.scene.build`
turns it into geometry, mesh and simulation, and :mod:`fdem.scene.write` writes one back.
"""
from __future__ import annotations

import math
import numbers
import tomllib
from dataclasses import dataclass
from pathlib import Path

__all__ = ["SceneError", "Key", "SCHEMA", "JOINT_KINDS", "SLOPE_KINDS", "SUPPORT_KINDS", "read_scene",
           "check_scene", "schema_markdown"]


class SceneError(ValueError):
    """A scene file that cannot run: the message names the file, the section and the key."""


@dataclass(frozen=True)
class Key:
    """One key of a section: ``kind`` is ``"float"``, ``"int"``, ``"bool"``, ``"str"``,
    ``"floats"`` (a list of numbers, ``length`` of them when given), ``"points"`` (a list of
    ``[x, y]``), ``"rows"`` (a list of lists of ``length`` numbers) or ``"any"`` (checked by
    the section's own rule); ``low``/``high`` bound numbers (``open_low``/``open_high``: the
    bound itself is refused); ``choices`` lists the allowed strings."""

    kind: str
    help: str
    default: object = None
    required: bool = False
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    open_high: bool = False
    choices: tuple = ()
    length: int | None = None


def _f(help, default=None, required=False, low=None, high=None, open_low=False, open_high=False) -> Key:
    return Key("float", help, default, required, low, high, open_low, open_high)


POSITIVE = dict(low=0.0, open_low=True)
ANGLE = dict(low=0.0, high=90.0, open_high=True)
FRACTION = dict(low=0.0, high=1.0, open_low=True)

SLOPE_KINDS = ("simple", "benched", "polygon")
SUPPORT_KINDS = ("fixed", "fix-x", "fix-y", "free")
JOINT_KINDS = ("persistent", "intermittent", "brick", "segments", "stochastic")

SCHEMA: dict[str, dict[str, Key]] = {
    "scene": {
        "name": Key("str", "label of the scene in the outputs (default: the file's stem)"),
        "description": Key("str", "free text", default=""),
        "size": _f("target element size [m]", required=True, **POSITIVE),
        "min_joint_length": _f("joint pieces shorter than this are dropped [m]", 0.0, low=0.0),
        "refine_near_joints": _f("element size factor on the joints (0, 1]", low=0.0, high=1.0, open_low=True),
        "order": Key("str", "memory order of the mesh", default="hilbert", choices=("hilbert", "morton", "none")),
        "mesh": Key("str", "a Gmsh .msh file to use instead of [slope] and [[joints]] (path relative to the "
                           "scene file)"),
    },
    "slope": {
        "kind": Key("str", "outline builder", default="simple", choices=SLOPE_KINDS),
        "height": _f("slope height [m] (simple)", **POSITIVE),
        "face_angle": _f("face angle [deg] (simple)", low=0.0, high=90.0, open_low=True),
        "benches": Key("rows", "[height m, face angle deg, berm m] per bench from the toe up (benched)", length=3),
        "crest_length": _f("crest plateau behind the face [m] (simple, benched)", **POSITIVE),
        "toe_length": _f("floor in front of the toe [m] (simple, benched)", **POSITIVE),
        "base_depth": _f("rock below the toe [m] (simple, benched)", **POSITIVE),
        "vertices": Key("points", "outline corners [[x, y], ...] [m], toe on the left (polygon)"),
    },
    "joints": {  # one table per joint set, [[joints]]; set j (1, 2, ...) is the j-th table
        "kind": Key("str", "joint-set generator", required=True, choices=JOINT_KINDS),
        "name": Key("str", "label"),
        "dip": Key("any", "trace angle from +x [deg], in [0, 180) (stochastic: [\"fixed\", a] | "
                          "[\"normal\", mean, sd] | [\"uniform\", lo, hi])"),
        "spacing": _f("normal spacing [m] (persistent, brick)", **POSITIVE),
        "offset": _f("normal offset n.x of one joint [m] (persistent, intermittent, brick)"),
        "through_toe": _f("instead of offset: the fraction of the spacing between the toe and the joint "
                          "below it (0 puts a joint through the toe)", low=0.0, high=1.0, open_high=True),
        "cross_spacing": _f("cross-joint spacing along a layer [m] (brick; default 2 spacing)", **POSITIVE),
        "cross_dip": _f("cross-joint angle [deg] (brick; default dip + 90)", low=0.0, high=180.0, open_high=True),
        "phase": _f("shift along the traces [m] (intermittent, brick)", 0.0),
        "trace_length": _f("joint length [m] (intermittent)", **POSITIVE),
        "bridge_length": _f("rock bridge between joints of a row [m] (intermittent)", low=0.0),
        "row_spacing": _f("normal spacing of the rows [m] (intermittent)", **POSITIVE),
        "stagger": _f("shift of each row along its trace [m] (intermittent)", 0.0),
        "rows": Key("floats", "first and last row kept (intermittent)", length=2),
        "segments": Key("rows", "[x0, y0, x1, y1] per joint [m] (segments)", length=4),
        "count": Key("int", "number of joints (stochastic)", low=1),
        "length": Key("any", "trace length [m] (stochastic): [\"fixed\", L] | [\"lognormal\", mean, sd] | "
                             "[\"exponential\", mean] | [\"uniform\", lo, hi]"),
        "seed": Key("int", "random seed (stochastic)", default=0, low=0),
        "region": Key("floats", "[x0, y0, x1, y1] of the joint centres (stochastic; default the model)", length=4),
        "side_band": _f("width of the intact bands kept free of these joints along the left and right "
                        "boundaries [m] (any kind; default none): slip at the rollers stays out of the mechanism",
                        **POSITIVE),
    },
    "mesh": {  # only with scene.mesh
        "joints": Key("any", "{group name = joint-set tag} of the mesh's joint curves"),
        "toe": Key("floats", "[x, y] of the slope toe [m], for the runout figures", length=2),
    },
    "rock": {
        "young": _f("Young's modulus [Pa]", required=True, **POSITIVE),
        "poisson": _f("Poisson's ratio [-]", required=True, low=0.0, high=0.5, open_high=True),
        "density": _f("density [kg/m^3]", required=True, **POSITIVE),
        "damping": _f("element damping, a fraction of each triangle's critical viscosity (docs/damping.md; "
                      "omitted: none)", low=0.0),
        "elastic_side_bands": _f("width [m] of bands along the left and right boundaries whose intact crack "
                                 "elements stay elastic, never softening or breaking: a far field that carries "
                                 "the rollers' load (omitted: none; keep the joints out with side_band)",
                                 **POSITIVE),
    },
    "cracks": {  # one table per tag, [cracks.0] intact rock bridges, [cracks.1] joint set 1, ...
        "name": Key("str", "label", default=""),
        "f_t": _f("tensile strength [Pa]", required=True, **POSITIVE),
        "c": _f("cohesion [Pa]", required=True, low=0.0),
        "phi": _f("friction angle [deg]", required=True, **ANGLE),
        "G_I": _f("mode-I fracture energy [J/m^2]", required=True, **POSITIVE),
        "G_II": _f("mode-II fracture energy [J/m^2]", required=True, low=0.0),
        "p_n": _f("normal penalty [Pa] (k_n = p_n / L0)", **POSITIVE),
        "p_t": _f("tangential penalty [Pa]", **POSITIVE),
        "k_n": _f("normal stiffness per unit area [Pa/m] (instead of p_n)", **POSITIVE),
        "k_t": _f("tangential stiffness per unit area [Pa/m] (instead of p_t)", **POSITIVE),
        "phi_res": _f("residual friction angle of the broken faces [deg]", **ANGLE),
        "softening": Key("str", "softening curve", default="munjiza", choices=("munjiza", "linear")),
        "dilation_angle": _f("joint dilation angle [deg]", 0.0, **ANGLE),
        "dilation_limit": _f("slip after which dilation stops [m]", 0.0, low=0.0),
    },
    "contact": {
        "penalty": _f("contact penalty [Pa] (also the crack elements' contact penalty)", required=True, **POSITIVE),
        "friction_angle": _f("friction angle of contacts [deg]", 30.0, **ANGLE),
        "damping_ratio": _f("normal contact damping ratio [-]", 0.0, low=0.0, high=1.0),
    },
    "supports": {},  # {group = "fixed" | "fix-x" | "fix-y" | "free"}; checked by _check_supports
    "gravity": {
        "g": _f("gravitational acceleration, downward [m/s^2]", 9.81, low=0.0),
    },
    "heterogeneity": {
        "distribution": Key("str", "strength multipliers of f_t and c", default="none",
                            choices=("none", "normal", "weibull")),
        "cov": _f("coefficient of variation (normal) [-]", 0.1, low=0.0),
        "weibull_modulus": _f("Weibull shape m [-]", 10.0, **POSITIVE),
        "seed": Key("int", "random seed", default=0, low=0),
        "tags": Key("floats", "tags it applies to (default all)"),
        "min_factor": _f("smallest multiplier [-]", 0.05, low=0.0, high=1.0, open_low=True),
    },
    "start": {
        "kind": Key("str", "initial state: static equilibrium with pre-loaded crack elements, or unstressed",
                    default="static", choices=("static", "none")),
    },
    "workflow": {
        "kind": Key("str", "what the run does: strength reduction to failure, or gravity increase (fos is then the "
                           "gravity-factor bracket, required)", default="strength-reduction",
                    choices=("strength-reduction", "gravity-increase")),
        "reduction": Key("str", "damped steps of 10 %, the paper's rate, or none (the fos search is the whole analysis)",
                         default="steps", choices=("steps", "rate", "none")),
        "factors": Key("floats", "reduction factors F of the steps (default 1/0.9 ... 1/0.3)"),
        "reduction_rate": _f("fall of the strength 1/F per second (rate) [1/s]", 5.0, **POSITIVE),
        "final_strength": _f("strength 1/F the rate mode stops at [-]", 0.3, low=0.0, high=1.0, open_low=True,
                             open_high=True),
        "fos": Key("floats", "[lower, upper, tolerance]: search the factor of safety first (gravity-increase: the "
                             "gravity-factor bracket)", length=3),
        "equilibrium_ratio": _f("unbalanced-force ratio that counts as equilibrium [-]", 1e-4, low=0.0, high=1.0,
                                open_low=True, open_high=True),
        "equilibrium_hold": _f("response times the ratio must keep below equilibrium_ratio before a trial or "
                               "reduction step counts as converged [-] (0: the first check)", 0.0, low=0.0),
        "step_time": _f("cap of each damped stage [s] (default 5 response times)", **POSITIVE),
        "fail_displacement": _f("displacement that counts as failure [m] (default 1 % of the height)", **POSITIVE),
        "runout_time": _f("cap of the runout stage [s] (default from the height)", **POSITIVE),
        "rest_kinetic_ratio": _f("kinetic energy over its peak that counts as rest [-]", 0.01, low=0.0, high=1.0,
                                 open_low=True, open_high=True),
        "runout_dt_fraction": _f("time-step factor of the runout [-]", 0.8, **FRACTION),
        "trial_end": Key("str", "what a factor-of-safety trial that reaches its cap says: 'rest' it is followed "
                                "undamped and stands if it comes to rest having moved less than the failure "
                                "displacement (the damped steps' rule), 'cap' it fails; unset: 'rest' for a "
                                "strength search, 'cap' for a gravity one", choices=("cap", "rest")),
        "runout_step": Key("str", "what the runout's time-step factor multiplies: the solver's bound on the critical "
                                  "step, or the critical step measured on the model when the runout starts and again every "
                                  "response time (1.26-1.63 times the bound on the four slopes; CPU only)", default="bound",
                           choices=("bound", "measured")),
        "local_fall_area": _f("area moved the failure displacement below which a fall that came to rest is a block "
                              "off the face and the reduction steps carry on [m^2] (default: none, any fall ends "
                              "them)", **POSITIVE),
        "reduce_tensile": Key("bool", "whether F divides the tensile strength f_t too (default: yes with reduction "
                                      "= steps, no with rate, the paper reducing cohesion and friction)"),
        "dt_fraction": _f("time-step factor of the other stages [-]", 0.8, **FRACTION),
        "density_scaling": _f("added-mass budget of the quasi-static stages, a fraction of the mass [-]", 0.01,
                              low=0.0, high=1.0),
        "max_time": _f("cap on the simulated time of the whole run [s]", **POSITIVE),
    },
    "monitors": {  # [[monitors]]: a point history each
        "name": Key("str", "column prefix in history.csv", required=True),
        "x": _f("x of the point [m] (reference configuration)", required=True),
        "y": _f("y of the point [m]", required=True),
    },
    "ensemble": {},  # checked by fdem.scene.ensemble when `fdem run ensemble --scene FILE` runs it
    "outputs": {
        "pictures": Key("bool", "write the PNG pictures", default=True),
        "toe": Key("floats", "[x, y] of the toe for the runout figures [m] (default: from the outline)", length=2),
    },
}
"""Every section and key a scene file may hold (``docs/scenes.md`` prints this table)."""

ARRAYS = ("joints", "monitors")       # [[section]]: a list of tables
BY_TAG = ("cracks",)                  # [section.<tag>]: tables keyed by an integer tag
FREE_KEYS = ("supports",)             # {name = value}: keys are the user's group names
OWN_CHECK = ("ensemble",)             # checked by its own module (fdem.scene.ensemble), kept as given
REQUIRED_SECTIONS = ("scene", "rock", "cracks", "contact")

_JOINT_KEYS = {
    "persistent": {"dip", "spacing"},
    "intermittent": {"dip", "trace_length", "bridge_length", "row_spacing"},
    "brick": {"dip", "spacing"},
    "segments": {"segments"},
    "stochastic": {"count", "length", "dip"},
}
_JOINT_OPTIONAL = {
    "persistent": {"offset", "through_toe", "name", "side_band"},
    "intermittent": {"stagger", "offset", "through_toe", "phase", "rows", "name", "side_band"},
    "brick": {"cross_spacing", "cross_dip", "offset", "through_toe", "phase", "name", "side_band"},
    "segments": {"name", "side_band"},
    "stochastic": {"seed", "region", "name", "side_band"},
}
_SLOPE_KEYS = {
    "simple": {"height", "face_angle", "crest_length", "toe_length", "base_depth"},
    "benched": {"benches", "crest_length", "toe_length", "base_depth"},
    "polygon": {"vertices"},
}


# ----------------------------------------------------------------------------- reading
def read_scene(path: str | Path) -> dict:
    """Read and check the scene file ``path`` (:func:`check_scene`); a :class:`SceneError` names
    the file and, for TOML syntax, the line."""
    path = Path(path)
    if not path.is_file():
        raise SceneError(f"{path}: no such scene file")
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"{path}: not valid TOML: {err}") from None
    except UnicodeDecodeError as err:
        raise SceneError(f"{path}: not a text file: {err}") from None
    return check_scene(raw, path)


def check_scene(raw: dict, path: str | Path = "<scene>") -> dict:
    """The scene ``raw`` (a parsed TOML document) checked against :data:`SCHEMA`, defaults filled.

    Returns a new ``dict``: one ``dict`` per section (``joints`` and ``monitors`` lists of them,
    ``cracks`` keyed by ``int`` tag), ``scene.name`` defaulting to the file's stem and
    ``scene.mesh`` resolved against the file's folder. Raises :class:`SceneError`."""
    path = Path(path)
    where = str(path)
    unknown = sorted(set(raw) - set(SCHEMA))
    if unknown:
        raise SceneError(f"{where}: unknown section(s) {', '.join(f'[{u}]' for u in unknown)}; the sections are: "
                         f"{', '.join(SCHEMA)}")
    for s in REQUIRED_SECTIONS:
        if s not in raw:
            raise SceneError(f"{where}: the section [{s}] is missing (required: "
                             f"{', '.join(f'[{r}]' for r in REQUIRED_SECTIONS)})")
    out: dict = {}
    for section, keys in SCHEMA.items():
        value = raw.get(section)
        if section in ARRAYS:
            tables = [] if value is None else value
            if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
                raise SceneError(f"{where}: [[{section}]] must be an array of tables (write [[{section}]] "
                                 "before each one)")
            out[section] = [_check_table(t, keys, f"{where}: [[{section}]] #{i + 1}") for i, t in enumerate(tables)]
        elif section in BY_TAG:
            out[section] = _check_by_tag(value, keys, where, section)
        elif section in FREE_KEYS:
            out[section] = _check_supports(value if value is not None else {}, where)
        elif section in OWN_CHECK:
            if value is not None and not isinstance(value, dict):
                raise SceneError(f"{where}: {section} must be a table [{section}]")
            out[section] = value
        else:
            if value is not None and not isinstance(value, dict):
                raise SceneError(f"{where}: {section} must be a table [{section}], got {value!r}")
            out[section] = _check_table(value or {}, keys, f"{where}: [{section}]")
    _check_relations(out, raw, path)
    return out


def _check_table(table: dict, keys: dict[str, Key], where: str) -> dict:
    unknown = sorted(set(table) - set(keys))
    if unknown:
        raise SceneError(f"{where}: unknown key(s) {', '.join(unknown)}; the keys are: {', '.join(keys)}")
    out = {}
    for name, key in keys.items():
        if name in table:
            out[name] = _check_value(table[name], key, f"{where} {name} = {table[name]!r}")
        elif key.required:
            raise SceneError(f"{where}: the key {name} is missing ({key.help})")
        else:
            out[name] = key.default
    return out


def _number(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def _check_value(value, key: Key, where: str):
    if key.kind == "any":
        return value
    if key.kind == "bool":
        if not isinstance(value, bool):
            raise SceneError(f"{where}: must be true or false ({key.help})")
        return value
    if key.kind == "str":
        if not isinstance(value, str):
            raise SceneError(f"{where}: must be a string in quotes ({key.help})")
        if key.choices and value not in key.choices:
            raise SceneError(f"{where}: must be one of {', '.join(map(repr, key.choices))} ({key.help})")
        return value
    if key.kind in ("float", "int"):
        if key.kind == "int" and not (isinstance(value, int) and not isinstance(value, bool)):
            raise SceneError(f"{where}: must be a whole number ({key.help})")
        if not _number(value) or not math.isfinite(value):
            raise SceneError(f"{where}: must be a finite number ({key.help})")
        _check_range(value, key, where)
        return float(value) if key.kind == "float" else int(value)
    if key.kind == "floats":
        if not isinstance(value, list) or not all(_number(v) and math.isfinite(v) for v in value):
            raise SceneError(f"{where}: must be a list of finite numbers ({key.help})")
        if key.length is not None and len(value) != key.length:
            raise SceneError(f"{where}: must hold {key.length} numbers, got {len(value)} ({key.help})")
        return [float(v) for v in value]
    if key.kind in ("points", "rows"):
        n = 2 if key.kind == "points" else key.length
        if (not isinstance(value, list) or not value
                or not all(isinstance(r, list) and len(r) == n and all(_number(v) and math.isfinite(v) for v in r)
                           for r in value)):
            raise SceneError(f"{where}: must be a list of [{', '.join(['number'] * n)}] rows ({key.help})")
        return [[float(v) for v in r] for r in value]
    raise AssertionError(f"unknown key kind {key.kind!r}")


def _check_range(value: float, key: Key, where: str) -> None:
    low_ok = key.low is None or (value > key.low if key.open_low else value >= key.low)
    high_ok = key.high is None or (value < key.high if key.open_high else value <= key.high)
    if low_ok and high_ok:
        return
    if key.low is not None and key.high is not None:
        rng = f"in {'(' if key.open_low else '['}{key.low:g}, {key.high:g}{')' if key.open_high else ']'}"
    elif key.low is not None:
        rng = f"{'>' if key.open_low else '>='} {key.low:g}"
    else:
        rng = f"{'<' if key.open_high else '<='} {key.high:g}"
    raise SceneError(f"{where}: must be {rng} ({key.help})")


def _check_by_tag(value, keys: dict[str, Key], where: str, section: str) -> dict[int, dict]:
    if not isinstance(value, dict) or not value:
        raise SceneError(f"{where}: [{section}] needs one table per tag: [{section}.0] for the intact rock "
                         f"bridges, [{section}.1] for joint set 1, ...")
    out = {}
    for tag, table in value.items():
        if not (isinstance(tag, str) and tag.isdigit()):
            raise SceneError(f"{where}: [{section}.{tag}]: the tag must be a whole number >= 0 "
                             f"(0 intact rock bridges, j joint set j)")
        if not isinstance(table, dict):
            raise SceneError(f"{where}: [{section}.{tag}] must be a table")
        out[int(tag)] = _check_table(table, keys, f"{where}: [{section}.{tag}]")
    return dict(sorted(out.items()))


def _check_supports(value, where: str) -> dict[str, str]:
    if not isinstance(value, dict):
        raise SceneError(f"{where}: [supports] must be a table of group = kind")
    for group, kind in value.items():
        if kind not in SUPPORT_KINDS:
            raise SceneError(f"{where}: [supports] {group} = {kind!r}: must be one of "
                             f"{', '.join(map(repr, SUPPORT_KINDS))} (fix-x holds the x displacement: a "
                             "roller on a vertical side)")
    return dict(value)


def _check_relations(s: dict, raw: dict, path: Path) -> None:
    """Rules between keys: what each slope and joint kind needs, tags against joint sets, mesh
    against outline, the objects' own checks (a ``ValueError`` of a constructor becomes a
    :class:`SceneError` naming the section)."""
    where = str(path)
    sc = s["scene"]
    if sc["name"] is None:
        sc["name"] = path.stem if path.suffix else "scene"
    if sc["mesh"] is not None:
        mesh = Path(sc["mesh"])
        sc["mesh"] = str(mesh if mesh.is_absolute() else (path.parent / mesh))
        for section in ("slope", "joints"):
            if raw.get(section):
                raise SceneError(f"{where}: [scene] mesh = {raw['scene']['mesh']!r} replaces the outline and the "
                                 f"joints: remove [{section}] (joint curves come from the mesh's groups, [mesh] "
                                 "joints)")
        if not Path(sc["mesh"]).is_file():
            raise SceneError(f"{where}: [scene] mesh = {raw['scene']['mesh']!r}: no such file ({sc['mesh']})")
        joints = s["mesh"]["joints"] or {}
        if not isinstance(joints, dict) or not all(isinstance(t, int) and not isinstance(t, bool) and t >= 1
                                                   for t in joints.values()):
            raise SceneError(f"{where}: [mesh] joints must map group names to joint-set tags >= 1, e.g. "
                             "joints = { bedding = 1, cross = 2 }")
        s["mesh"]["joints"] = dict(joints)
        n_sets = max(joints.values(), default=0)
    else:
        if raw.get("mesh"):
            raise SceneError(f"{where}: [mesh] is for a scene with [scene] mesh = \"file.msh\"")
        if "slope" not in raw:
            raise SceneError(f"{where}: the section [slope] is missing (or give [scene] mesh = \"file.msh\")")
        _check_slope(s["slope"], raw["slope"], where)
        for i, (js, js_raw) in enumerate(zip(s["joints"], raw.get("joints", [])), start=1):
            _check_joint_set(js, js_raw, f"{where}: [[joints]] #{i}")
        n_sets = len(s["joints"])
    tags = set(s["cracks"])
    needed = set(range(n_sets + 1))
    if needed - tags:
        missing = sorted(needed - tags)
        raise SceneError(f"{where}: no crack property set for tag(s) {missing}: give [cracks.{missing[0]}] "
                         f"(tag 0 the intact rock bridges, 1..{n_sets} the joint sets in the order given)")
    if tags - needed:
        extra = sorted(tags - needed)
        raise SceneError(f"{where}: [cracks.{extra[0]}] names a tag no joint set has (the scene has {n_sets} "
                         "joint set(s))")
    _construct_checks(s, where)
    if s["outputs"]["toe"] is None and s["mesh"]["toe"] is not None:
        s["outputs"]["toe"] = s["mesh"]["toe"]
    if sc["mesh"] is not None and s["outputs"]["toe"] is None:
        raise SceneError(f"{where}: a scene on its own mesh needs the toe for the runout figures: [mesh] "
                         "toe = [x, y]")
    names = [m["name"] for m in s["monitors"]]
    if len(set(names)) != len(names):
        raise SceneError(f"{where}: [[monitors]] names must differ, got {names}")


def _check_slope(slope: dict, raw: dict, where: str) -> None:
    kind = slope["kind"]
    needed, given = _SLOPE_KEYS[kind], {k for k in raw if k != "kind"}
    missing, extra = sorted(needed - given), sorted(given - needed)
    if missing:
        raise SceneError(f"{where}: [slope] kind = {kind!r} needs {', '.join(missing)}")
    if extra:
        raise SceneError(f"{where}: [slope] kind = {kind!r} takes no {', '.join(extra)} (it takes "
                         f"{', '.join(sorted(needed))})")


def _check_joint_set(js: dict, raw: dict, where: str) -> None:
    kind = js["kind"]
    needed, optional = _JOINT_KEYS[kind], _JOINT_OPTIONAL[kind]
    given = {k for k in raw if k != "kind"}
    missing, extra = sorted(needed - given), sorted(given - needed - optional)
    if missing:
        raise SceneError(f"{where}: kind = {kind!r} needs {', '.join(missing)}")
    if extra:
        raise SceneError(f"{where}: kind = {kind!r} takes no {', '.join(extra)} (it takes "
                         f"{', '.join(sorted(needed | optional))})")
    if "offset" in given and "through_toe" in given:
        raise SceneError(f"{where}: give offset or through_toe, not both")
    for name in set(js) - needed - optional - {"kind"}:  # defaults of keys this kind does not take
        del js[name]
    if kind != "stochastic":
        dip = js["dip"] if kind != "segments" else 0.0
        if not (_number(dip) and 0.0 <= dip < 180.0):
            raise SceneError(f"{where} dip = {dip!r}: must be a number in [0, 180) (trace angle from +x [deg])")
        js["dip"] = float(dip)
    else:
        for name, kinds in (("dip", ("fixed", "normal", "uniform")),
                            ("length", ("fixed", "lognormal", "exponential", "uniform"))):
            v = js[name]
            if not (isinstance(v, list) and v and v[0] in kinds and all(_number(p) for p in v[1:])):
                raise SceneError(f"{where} {name} = {v!r}: must be [kind, parameters...] with kind one of "
                                 f"{', '.join(map(repr, kinds))}")
            js[name] = [v[0]] + [float(p) for p in v[1:]]


def _construct_checks(s: dict, where: str) -> None:
    """Build the objects the run will build (property sets, joint sets, workflow, heterogeneity)
    so that their own checks (snap-back of a crack law, an inverted bracket, ...) speak now."""
    from fdem.scene.objects import crack_property_sets, heterogeneity, joint_sets, slope_polygon, workflow

    for what, fn in (("[cracks]", lambda: crack_property_sets(s)), ("[heterogeneity]", lambda: heterogeneity(s)),
                     ("[workflow]", lambda: workflow(s))):
        try:
            fn()
        except (ValueError, TypeError) as err:
            raise SceneError(f"{where}: {what}: {err}") from None
    if s["scene"]["mesh"] is None:
        try:
            polygon = slope_polygon(s)
        except (ValueError, TypeError) as err:
            raise SceneError(f"{where}: [slope]: {err}") from None
        try:
            joint_sets(s, polygon)
        except (ValueError, TypeError) as err:
            raise SceneError(f"{where}: [[joints]]: {err}") from None


def schema_markdown() -> str:
    """Every section and key as Markdown tables (``docs/scenes.md`` holds this text; a test keeps
    the two the same): key, type, default or "required", allowed values, meaning and unit."""
    def allowed(k: Key) -> str:
        if k.choices:
            return ", ".join(f"`{c}`" for c in k.choices)
        if k.low is not None or k.high is not None:
            lo = "" if k.low is None else f"{'>' if k.open_low else '>='} {k.low:g}"
            hi = "" if k.high is None else f"{'<' if k.open_high else '<='} {k.high:g}"
            return " and ".join(x for x in (lo, hi) if x)
        return f"{k.length} numbers" if k.length else ""

    heads = {"joints": "[[joints]] (one table per joint set; set j is tag j)",
             "cracks": "[cracks.TAG] (0 intact rock bridges, j joint set j)",
             "monitors": "[[monitors]] (one table per point history)",
             "supports": "[supports]", "ensemble": "[ensemble]"}
    out = []
    for section, keys in SCHEMA.items():
        out.append(f"#### {heads.get(section, f'[{section}]')}\n")
        if section == "ensemble":
            out.append("Read only by `fdem run ensemble --scene FILE`: `n`, `seed`, `method` (`lhs`, `mc`), "
                       "`fos` ([lower, upper, tolerance]), `runout` (true: run the workflow after the search) "
                       "and the table `[ensemble.vary]` of dotted paths and distributions (section Ensembles "
                       "above).\n")
            continue
        if section == "supports":
            out.append("One line per boundary group: `group = \"kind\"` with kind one of "
                       + ", ".join(f"`{k}`" for k in SUPPORT_KINDS) + " (`fix-x` holds the x displacement: a "
                       "roller on a vertical side). An outline's groups are `bottom`, `left`, `right`, "
                       "`surface`; a mesh's are its physical curves.\n")
            continue
        out.append("| key | type | default | allowed | meaning [unit] |\n|---|---|---|---|---|")
        for name, k in keys.items():
            default = "required" if k.required else ("" if k.default is None else f"`{k.default!r}`")
            out.append(f"| `{name}` | {k.kind} | {default} | {allowed(k)} | {k.help.replace('|', '/')} |")
        out.append("")
    return "\n".join(out).rstrip() + "\n"
