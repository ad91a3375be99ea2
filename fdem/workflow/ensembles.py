"""Stochastic DFN ensembles on Dask: distributions of the factor of safety and runout, and the
probability of failure, over the joint networks and strengths consistent with the field data.

An :class:`Ensemble` names a *scene* (a picklable callable, ``scene(**parameters)``, that
meshes a slope and brings it to equilibrium with :func:`fdem.solve.geostatic.geostatic_start`,
returning the :class:`fdem.solve.simulation.Simulation` or an object with a ``sim`` attribute) and the
:class:`Distribution` of each uncertain parameter (a :class:`fdem.geometry.joint_sets.StochasticSet`
seed, a trace length, an orientation scatter, a joint cohesion or friction angle, a
heterogeneity seed...). :meth:`Ensemble.sample` draws ``n`` parameter sets reproducibly from
``seed``:

* ``method="lhs"``: Latin hypercube (McKay, Beckman & Conover 1979) on the unit cube of the
  continuous parameters, ``scipy.stats.qmc.LatinHypercube(d, seed=seed)``, each row mapped
  through the inverse CDF of its distribution, ``x_j = F_j^{-1}(u_j)``;
* ``method="mc"``: plain Monte Carlo, ``u`` of realization ``i`` from
  ``numpy.random.default_rng([seed, i])`` (row ``i`` does not depend on ``n``).

Seed parameters (:meth:`Distribution.seed`) are integers in ``[0, 2**31)`` from
``numpy.random.default_rng([seed, i, k])`` for realization ``i`` and parameter ``k``; they take
no dimension of the hypercube.

:func:`run_ensemble` runs each realization as one Dask task (:func:`realize`: build the scene,
then :func:`fdem.workflow.fos.factor_of_safety`; optionally :func:`fdem.workflow.slope.run_slope_workflow`
and :func:`fdem.results.analysis.runout`) on a local ``dask.distributed`` cluster of single-threaded
worker processes (``NUMBA_NUM_THREADS=1`` in each worker's environment, set before Numba is
imported) or on a running cluster: a scheduler address, or the file a scheduler writes
(``dask scheduler --scheduler-file PATH``, the usual way on a batch system). Every worker,
local or remote, is held to one Numba thread by a worker plugin
(:class:`fdem.workflow.dask_workers.SingleThreadNumba`). Dask is an optional dependency
(``pip install "fdem[ensembles]"``), imported only here, when an ensemble runs. Rows stream into ``<out>/realizations.csv`` as
tasks finish (``as_completed``): the sampled parameters (``p_<name>``), the FoS and its
bracket, wall times, the worker's peak resident memory, the status and the error text. A
realization that raises (meshing, instability, a contradicted bracket) is a row with its error,
never the end of the ensemble. The table's first line carries the SHA-256 of the ensemble's
description (:meth:`Ensemble.fingerprint`); a rerun skips the realizations already in the table
and refuses a table of another description.

:func:`summarize` reads the table back: FoS statistics, the probability of failure
``P(FoS < 1)`` with its Wilson score interval (and the exact Clopper-Pearson interval for
comparison), the Spearman rank correlation of the FoS with each sampled parameter, runout
statistics where run, and PNG plots (histogram and empirical CDF, sensitivity scatter, the
failure pictures of the least and most stable realizations).
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import logging
import math
import os
import sys
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping
import numpy as np
from fdem.io.ensemble_table import finite_number, DESCRIPTION, TABLE, _HEADER, read_table

__all__ = ["DASK_MISSING", "Distribution", "Ensemble", "realize", "require_dask", "local_cluster",
           "check_scheduler_file", "connect", "EnsembleRun", "run_ensemble"]

DASK_MISSING = 'ensembles run on Dask, which is not installed: pip install "fdem[ensembles]"'
"""The message when Dask is missing: the one command that installs it."""


_KINDS = ("fixed", "uniform", "normal", "lognormal", "seed")


@dataclass(frozen=True)
class Distribution:
    """Distribution of one uncertain parameter. Build with the constructors:

    * :meth:`fixed` ``(value)``: always ``value``;
    * :meth:`uniform` ``(low, high)``: ``U(low, high)``, ``low < high``;
    * :meth:`normal` ``(mean, sd, low=None, high=None)``: ``N(mean, sd^2)``, truncated to
      ``[low, high]`` when bounds are given (``scipy.stats.truncnorm``: a parameter that must
      stay positive gets ``low=0``); ``sd > 0``;
    * :meth:`lognormal` ``(mean, sd)``: the variable's own mean and standard deviation (as in
      :class:`fdem.geometry.joint_sets.StochasticSet`): ``ln X ~ N(mu, s^2)``,
      ``s^2 = ln(1 + (sd/mean)^2)``, ``mu = ln(mean) - s^2/2``; ``mean > 0``, ``sd > 0``;
    * :meth:`seed` ``()``: an integer seed in ``[0, 2**31)`` (a DFN or heterogeneity seed).

    :meth:`check` raises ``ValueError`` naming the parameter for a negative or zero ``sd``,
    ``low >= high``, a NaN or infinite number, or an unknown kind.
    """

    kind: str
    a: float = math.nan
    b: float = math.nan
    low: float | None = None
    high: float | None = None

    @classmethod
    def fixed(cls, value: float) -> "Distribution":
        return cls("fixed", value)

    @classmethod
    def uniform(cls, low: float, high: float) -> "Distribution":
        return cls("uniform", low, high)

    @classmethod
    def normal(cls, mean: float, sd: float, low: float | None = None, high: float | None = None) -> "Distribution":
        return cls("normal", mean, sd, low, high)

    @classmethod
    def lognormal(cls, mean: float, sd: float) -> "Distribution":
        return cls("lognormal", mean, sd)

    @classmethod
    def seed(cls) -> "Distribution":
        return cls("seed")

    @property
    def continuous(self) -> bool:
        """Whether the parameter takes a dimension of the sampling hypercube."""
        return self.kind in ("uniform", "normal", "lognormal")

    def check(self, name: str) -> None:
        where = f"ensemble parameter {name!r}"
        if self.kind not in _KINDS:
            raise ValueError(f"{where}: unknown distribution {self.kind!r}; use one of {_KINDS}")
        if self.kind == "seed":
            return
        if not finite_number(self.a):
            raise ValueError(f"{where}: {self.kind} needs a finite first parameter, got {self.a!r}")
        if self.kind == "fixed":
            return
        if not finite_number(self.b):
            raise ValueError(f"{where}: {self.kind} needs a finite second parameter, got {self.b!r}")
        if self.kind == "uniform" and not self.a < self.b:
            raise ValueError(f"{where}: uniform needs low < high, got low {self.a!r} >= high {self.b!r}")
        if self.kind in ("normal", "lognormal") and not self.b > 0:
            raise ValueError(f"{where}: {self.kind} needs a standard deviation > 0, got {self.b!r}")
        if self.kind == "lognormal" and not self.a > 0:
            raise ValueError(f"{where}: lognormal needs a mean > 0, got {self.a!r}")
        if self.kind == "normal":
            for label, v in (("low", self.low), ("high", self.high)):
                if v is not None and not finite_number(v):
                    raise ValueError(f"{where}: truncation bound {label} must be finite, got {v!r}")
            if self.low is not None and self.high is not None and not self.low < self.high:
                raise ValueError(f"{where}: truncated normal needs low < high, got {self.low!r} >= {self.high!r}")
        elif self.low is not None or self.high is not None:
            raise ValueError(f"{where}: truncation bounds apply to the normal distribution only")

    def ppf(self, u: np.ndarray) -> np.ndarray:
        """Inverse CDF ``F^{-1}(u)`` of a continuous distribution at ``u`` in ``(0, 1)``."""
        from scipy import stats

        u = np.asarray(u, dtype=np.float64)
        if self.kind == "uniform":
            return self.a + (self.b - self.a) * u
        if self.kind == "normal":
            if self.low is None and self.high is None:
                return stats.norm.ppf(u, loc=self.a, scale=self.b)
            lo = -np.inf if self.low is None else (self.low - self.a) / self.b
            hi = np.inf if self.high is None else (self.high - self.a) / self.b
            return stats.truncnorm.ppf(u, lo, hi, loc=self.a, scale=self.b)
        if self.kind == "lognormal":
            s2 = math.log1p((self.b / self.a) ** 2)
            return stats.lognorm.ppf(u, math.sqrt(s2), scale=math.exp(math.log(self.a) - s2 / 2))
        raise ValueError(f"{self.kind} distribution has no inverse CDF to sample")

    def describe(self) -> list:
        return [self.kind, self.a, self.b, self.low, self.high]


# ----------------------------------------------------------------------------- the ensemble
def _callable_name(obj) -> str:
    """``module:qualname`` of a function, or of a dataclass instance's class with its fields."""
    def module_of(thing) -> str:
        # A scene defined in a script run as __main__ is named by the script's file name, so that
        # the script and a program importing it describe the same ensemble.
        module = getattr(thing, "__module__", "?")
        main = getattr(sys.modules.get("__main__"), "__file__", None)
        return Path(main).stem if module == "__main__" and main else module

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        cls = type(obj)
        fields = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
        return f"{module_of(cls)}:{cls.__qualname__}{json.dumps(fields, sort_keys=True, default=repr)}"
    name = getattr(obj, "__qualname__", None)
    if name is None or "<lambda>" in name or "<locals>" in name:
        raise ValueError(f"ensemble scene must be a module-level function or a dataclass instance (picklable, "
                         f"with a stable name for the description hash), got {obj!r}")
    return f"{module_of(obj)}:{name}"


# the SlopeWorkflow settings a search's trial is judged by
SEARCH_RULE = ("equilibrium_ratio", "equilibrium_hold", "step_time", "fail_displacement")


def _search_rule(wf=None) -> dict:
    """The :data:`SEARCH_RULE` settings of ``wf`` (default: a default SlopeWorkflow's), as floats
    (``equilibrium_hold=1`` and ``1.0`` are one rule, one fingerprint)."""
    from fdem.workflow.slope import SlopeWorkflow

    rule = {k: getattr(SlopeWorkflow() if wf is None else wf, k) for k in SEARCH_RULE}
    return {k: None if v is None else float(v) for k, v in rule.items()}


@dataclass(frozen=True)
class Ensemble:
    """Description of a stochastic ensemble (see the module docstring).

    scene : ``scene(**parameters)`` -> Simulation in equilibrium (or an object with ``sim``;
        a ``toe_x`` attribute [m] is used for the runout); a module-level function or a
        dataclass instance
    parameters : name -> :class:`Distribution`, passed to ``scene`` as keyword arguments
    n : number of realizations
    seed : seed of the sampling (and of the seed parameters)
    method : ``"lhs"`` (Latin hypercube) or ``"mc"`` (Monte Carlo)
    fos : ``(lower, upper, tol)`` of :func:`fdem.workflow.fos.factor_of_safety` (``lower`` must be
        stable, ``upper`` failing; a realization outside the bracket is recorded as
        ``below_bracket`` or ``above_bracket``)
    runout : a :class:`fdem.workflow.slope.SlopeWorkflow` to run after the FoS search (reduction to
        failure, runout to rest), or ``None``
    toe_x : toe abscissa [m] for :func:`fdem.results.analysis.runout` (default: the scene's ``toe_x``)
    pictures : return the failure picture of each realization (``fos_failure.png``)
    max_time : cap [s] on each trial's simulated time, or ``None`` (the trial's own cap, 5 T).
        A smoke setting (a followed trial's follow is capped there too): a capped trial counts as failing, so realizations end
        ``below_bracket``; the cap is part of the description, so it never mixes with real runs
    search : a :class:`fdem.workflow.slope.SlopeWorkflow` whose trial rule judges the search's
        trials (its ``equilibrium_ratio``, ``equilibrium_hold``, ``step_time`` and
        ``fail_displacement``, :func:`fdem.workflow.slope.trial_stage`, and what a capped trial
        says, :attr:`~fdem.workflow.slope.SlopeWorkflow.trial_rule`), as ``fdem run`` judges the
        scene's own search; ``None``: the default trial
        (:func:`fdem.workflow.fos.default_trial_stage`), followed to rest when capped as a default
        workflow's is
    """

    scene: Callable
    parameters: Mapping[str, Distribution]
    n: int
    seed: int = 0
    method: str = "lhs"
    fos: tuple[float, float, float] = (0.5, 3.0, 0.02)
    runout: object = None
    toe_x: float | None = None
    pictures: bool = True
    max_time: float | None = None
    search: object = None

    def __post_init__(self):
        object.__setattr__(self, "parameters", dict(self.parameters))
        if not callable(self.scene):
            raise ValueError(f"ensemble scene must be callable, got {self.scene!r}")
        _callable_name(self.scene)
        if isinstance(self.n, bool) or int(self.n) != self.n or self.n < 1:
            raise ValueError(f"ensemble n must be a positive integer, got {self.n!r}")
        if isinstance(self.seed, bool) or int(self.seed) != self.seed or self.seed < 0:
            raise ValueError(f"ensemble seed must be a non-negative integer, got {self.seed!r}")
        if self.method not in ("lhs", "mc"):
            raise ValueError(f"ensemble method must be 'lhs' or 'mc', got {self.method!r}")
        for name, dist in self.parameters.items():
            if not isinstance(dist, Distribution):
                raise ValueError(f"ensemble parameter {name!r}: expected a Distribution, got {dist!r}")
            if not name.isidentifier():
                raise ValueError(f"ensemble parameter {name!r} is not a valid keyword-argument name")
            dist.check(name)
        lower, upper, tol = self.fos
        if not (finite_number(lower) and finite_number(upper) and finite_number(tol) and 0 < lower < upper and tol > 0):
            raise ValueError(f"ensemble fos bracket must be 0 < lower < upper with tol > 0, got {self.fos!r}")
        if self.max_time is not None and not (finite_number(self.max_time) and self.max_time > 0):
            raise ValueError(f"ensemble max_time must be a positive number of seconds, got {self.max_time!r}")
        if self.search is not None and not all(hasattr(self.search, k) for k in SEARCH_RULE):
            raise ValueError(f"ensemble search must be a SlopeWorkflow (its trial rule judges the search), "
                             f"got {self.search!r}")

    def describe(self) -> dict:
        """Everything that decides the results, as JSON-ready data (the hash covers this)."""
        wf = self.runout
        return {"scene": _callable_name(self.scene),
                "parameters": {k: v.describe() for k, v in sorted(self.parameters.items())},
                "n": int(self.n), "seed": int(self.seed), "method": self.method, "fos": list(self.fos),
                "runout": None if wf is None else repr(wf), "toe_x": self.toe_x,
                # only when set, so the fingerprints of existing uncapped ensembles stay the same
                **({"max_time": float(self.max_time)} if self.max_time is not None else {}),
                # only when not the default trial's, so that the fingerprints of ensembles judged by
                # it stay as they were before the rule was kept
                **({"search": _search_rule(self.search)} if _search_rule(self.search) != _search_rule() else {}),
                # only when followed, so that ensembles judged at the cap keep their fingerprints
                # and those judged at rest never mix with them
                **({"trial_end": "rest"} if self.trial_rule == "rest" else {})}

    @property
    def trial_rule(self) -> str:
        """What a realization's capped trial says: the search's ``trial_end`` when it gives one,
        else ``"rest"``, a strength search's default
        (:attr:`~fdem.workflow.slope.SlopeWorkflow.trial_rule`): every realization's search is a
        strength search, also for a scene whose own workflow increases gravity."""
        return getattr(self.search, "trial_end", None) or "rest"

    def fingerprint(self) -> str:
        """SHA-256 of :meth:`describe` (canonical JSON)."""
        text = json.dumps(self.describe(), sort_keys=True, default=repr, allow_nan=True)
        return hashlib.sha256(text.encode()).hexdigest()

    def sample(self) -> list[dict]:
        """The ``n`` parameter sets (module docstring); the same on every call."""
        names = list(self.parameters)
        cont = [k for k in names if self.parameters[k].continuous]
        d = len(cont)
        if d and self.method == "lhs":
            from scipy.stats import qmc

            u = qmc.LatinHypercube(d=d, seed=np.random.default_rng(self.seed)).random(self.n)
        elif d:
            u = np.array([np.random.default_rng([self.seed, i]).random(d) for i in range(self.n)])
        else:
            u = np.zeros((self.n, 0))
        cols = {k: self.parameters[k].ppf(u[:, j]) for j, k in enumerate(cont)}
        rows = []
        for i in range(self.n):
            row = {}
            for k_idx, k in enumerate(names):
                dist = self.parameters[k]
                if dist.kind == "fixed":
                    row[k] = dist.a
                elif dist.kind == "seed":
                    row[k] = int(np.random.default_rng([self.seed, i, k_idx]).integers(0, 2 ** 31))
                else:
                    row[k] = float(cols[k][i])
            rows.append(row)
        return rows


# ----------------------------------------------------------------------------- one realization
def _peak_rss_mb() -> float:
    """Peak resident set size of this process so far [MiB] (``getrusage``; Linux reports kiB)."""
    try:
        import resource

        kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        return kb / 1024.0 if sys.platform != "darwin" else kb / 2 ** 20
    except ImportError:  # pragma: no cover - not on POSIX
        return math.nan


def realize(ensemble: Ensemble, index: int, params: dict) -> dict:
    """Run realization ``index`` with ``params``: the scene, the FoS search and, if asked, the
    slope workflow and runout. Never raises: an exception becomes ``status="error"`` with its
    text (``below_bracket`` / ``above_bracket`` when the FoS search's bracket is contradicted).

    Returns the table row (see :func:`run_ensemble`) and, under ``"_picture"``, the PNG bytes
    of the first failing trial when ``ensemble.pictures``.
    """
    t0 = time.perf_counter()
    row = {"index": int(index), "status": "ok", "fos": math.nan, "fos_lower": math.nan, "fos_upper": math.nan,
           "n_trials": 0, "n_triangles": 0, "build_s": math.nan, "fos_s": math.nan,
           "runout_distance_m": math.nan, "runout_volume_m2": math.nan, "outcome": "",
           "wall_s": math.nan, "peak_rss_mb": math.nan, "worker_pid": os.getpid(), "numba_threads": 0,
           "error": ""}
    row.update({f"p_{k}": v for k, v in params.items()})
    picture = None
    try:
        import numba

        want = int(os.environ.get("NUMBA_NUM_THREADS", numba.config.NUMBA_NUM_THREADS))
        if numba.get_num_threads() > want:
            numba.set_num_threads(want)
        row["numba_threads"] = numba.get_num_threads()
        from fdem.workflow.fos import default_trial_stage, factor_of_safety

        built = ensemble.scene(**params)
        sim = getattr(built, "sim", built)
        row["n_triangles"] = int(sim.model.topology.n_triangles)
        t1 = time.perf_counter()
        row["build_s"] = t1 - t0
        lower, upper, tol = ensemble.fos
        try:
            with tempfile.TemporaryDirectory() as tmp:
                from fdem.workflow.slope import SlopeWorkflow, stage_rules, trial_follow, trial_stage

                trial = None
                if ensemble.search is not None:  # the scene's own trial rule, as its fdem run judges it
                    trial = trial_stage(sim, ensemble.search)
                wf = ensemble.search or SlopeWorkflow()
                follow = trial_follow(wf, stage_rules(sim, wf), ensemble.trial_rule)
                if ensemble.max_time is not None:  # the smoke cap holds a follow too
                    trial = trial or default_trial_stage(sim)
                    trial = dataclasses.replace(trial, max_time=min(trial.max_time, ensemble.max_time))
                    if follow is not None:
                        follow = dataclasses.replace(follow, max_time=min(follow.max_time, ensemble.max_time))
                res = factor_of_safety(sim, lower, upper, tol=tol, trial=trial, follow=follow,
                                       out_dir=tmp if ensemble.pictures else None)
                png = Path(tmp) / "fos_failure.png"
                if png.exists():
                    picture = png.read_bytes()
            row.update(fos=res.fos, fos_lower=res.bracket[0], fos_upper=res.bracket[1], n_trials=len(res.trials))
        except ValueError as exc:
            text = str(exc)
            if "already fails at the lower factor" in text:
                row.update(status="below_bracket", fos_lower=0.0, fos_upper=lower, error=text)
            elif "still stable at the upper factor" in text:
                row.update(status="above_bracket", fos_lower=upper, fos_upper=math.inf, error=text)
            else:
                raise
        row["fos_s"] = time.perf_counter() - t1
        if ensemble.runout is not None:
            from fdem.results.analysis import runout
            from fdem.workflow.slope import run_slope_workflow

            summary = run_slope_workflow(sim, ensemble.runout)
            row["outcome"] = summary["outcome"]
            toe = ensemble.toe_x if ensemble.toe_x is not None else getattr(built, "toe_x", None)
            if summary["outcome"] == "failed" and toe is not None:
                r = runout(sim.model.topology, sim.state.x, toe)
                row["runout_distance_m"], row["runout_volume_m2"] = r["runout_distance_m"], r["runout_volume_m2"]
            elif summary["outcome"] in ("stable", "crept"):  # crept a little and came to rest: no runout
                row["runout_distance_m"], row["runout_volume_m2"] = 0.0, 0.0
    except Exception as exc:  # noqa: BLE001 - any failure of one realization is data, not the end
        row["status"] = "error"
        tb = traceback.extract_tb(exc.__traceback__)
        where = f" at {Path(tb[-1].filename).name}:{tb[-1].lineno}" if tb else ""
        row["error"] = f"{type(exc).__name__}: {exc}{where}"
    row["wall_s"] = time.perf_counter() - t0
    row["peak_rss_mb"] = _peak_rss_mb()
    row["_picture"] = picture
    return row


# ----------------------------------------------------------------------------- the table
def _columns(ensemble: Ensemble) -> list[str]:
    base = ["index", "status", "fos", "fos_lower", "fos_upper", "n_trials", "n_triangles", "build_s", "fos_s",
            "runout_distance_m", "runout_volume_m2", "outcome", "wall_s", "peak_rss_mb", "worker_pid",
            "numba_threads", "error"]
    return base[:2] + [f"p_{k}" for k in ensemble.parameters] + base[2:]


def _check_table(path: Path, digest: str) -> set[int]:
    """Indices already in the table at ``path``; a table of another description is refused."""
    if not path.exists():
        return set()
    found, rows = read_table(path)
    if found != digest:
        raise ValueError(f"{path} holds results of another ensemble description (sha256 {found or 'missing'}, "
                         f"this one {digest}): write to another directory or delete the table")
    return {r["index"] for r in rows}


# ----------------------------------------------------------------------------- Dask
def require_dask() -> None:
    """Import ``dask.distributed`` or raise ``ImportError`` with :data:`DASK_MISSING` (the pip
    command), before any work starts."""
    try:
        import dask.distributed  # noqa: F401
    except ImportError as err:
        raise ImportError(f"{DASK_MISSING} ({err})") from None


def local_cluster(n_workers: int = 2, **kwargs):
    """A local ``dask.distributed`` cluster of ``n_workers`` processes with one thread each and
    ``NUMBA_NUM_THREADS=1`` (``OMP_NUM_THREADS=1``) in their environment, which the worker
    processes inherit at start, before anything imports Numba. The client's import path
    (``sys.path``) is passed as ``PYTHONPATH`` so the workers unpickle what the client can import
    (a scene defined next to a case script)."""
    from dask.distributed import LocalCluster

    if int(n_workers) < 1:
        raise ValueError(f"n_workers must be >= 1, got {n_workers}")
    path = [p for p in sys.path if p and os.path.isdir(p)]
    env = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
           "PYTHONPATH": os.pathsep.join(path)}
    env.update(kwargs.pop("env", {}))
    opts = dict(n_workers=int(n_workers), threads_per_worker=1, processes=True, env=env, dashboard_address=None,
                silence_logs=logging.ERROR)
    opts.update(kwargs)
    return LocalCluster(**opts)


def check_scheduler_file(path) -> Path:
    """``path`` as a ``Path`` if it is a readable scheduler file (JSON with an ``address``, as
    ``dask scheduler --scheduler-file`` writes it); a ``FileNotFoundError`` or ``ValueError``
    naming the file otherwise. Cheap, so callers check before any other work."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"Dask scheduler file {str(path)!r} does not exist (start the scheduler with "
                                f"`dask scheduler --scheduler-file {path}` first); nothing was run")
    try:
        address = json.loads(path.read_text()).get("address")
    except (OSError, ValueError, AttributeError) as exc:
        raise ValueError(f"Dask scheduler file {str(path)!r} is not a scheduler's JSON file ({exc}); "
                         "nothing was run") from None
    if not address:
        raise ValueError(f"Dask scheduler file {str(path)!r} names no scheduler address; nothing was run")
    return path


def connect(address: str | None = None, timeout: float = 10.0, scheduler_file=None):
    """A ``dask.distributed.Client`` on the scheduler at ``address``, or on the one that wrote
    ``scheduler_file`` (:func:`check_scheduler_file`); a ``ConnectionError`` naming the address
    or file if the scheduler does not answer within ``timeout`` [s]."""
    require_dask()
    from dask.distributed import Client

    if scheduler_file is not None:
        where = f"named in {str(check_scheduler_file(scheduler_file))!r}"
        kwargs = dict(scheduler_file=str(scheduler_file))
    else:
        where = f"at {address!r}"
        kwargs = dict(address=address)
    try:
        return Client(timeout=f"{float(timeout)}s", **kwargs)
    except (OSError, TimeoutError) as exc:
        raise ConnectionError(f"the Dask scheduler {where} did not answer within {timeout:g} s "
                              f"({type(exc).__name__}: {exc}); nothing was run") from None


@dataclass
class EnsembleRun:
    """What :func:`run_ensemble` did: the table, how many tasks it ran now, how many it skipped
    (already in the table), and the wall time [s]."""

    table: Path
    n_run: int
    n_skipped: int
    wall_seconds: float
    rows: list[dict] = field(default_factory=list)


def run_ensemble(ensemble: Ensemble, out, workers: int = 2, scheduler: str | None = None, client=None,
                 timeout: float = 10.0, progress: bool = True, scheduler_file=None) -> EnsembleRun:
    """Run every realization of ``ensemble`` not yet in ``<out>/realizations.csv`` as one Dask task.

    Cluster: ``client`` if given, else the scheduler that wrote ``scheduler_file`` or the one at
    ``scheduler`` (:func:`connect`, refused within ``timeout`` if it does not answer), else
    :func:`local_cluster` with ``workers`` processes. Every worker is held to one Numba thread
    (:class:`fdem.workflow.dask_workers.SingleThreadNumba`). Rows are appended as tasks finish;
    a failing pictures' PNG goes to ``<out>/realizations/<index>_failure.png``.
    ``<out>/ensemble.json`` holds the description and its hash; the table's first line the hash.
    Checks (Dask installed, scheduler file, description, table, scheduler) all happen before any
    task runs.
    """
    require_dask()
    if scheduler_file is not None:
        check_scheduler_file(scheduler_file)
    from dask.distributed import Client, as_completed

    from fdem.workflow.dask_workers import register_single_thread

    out = Path(out)
    digest = ensemble.fingerprint()
    table = out / TABLE
    done = _check_table(table, digest)
    samples = ensemble.sample()
    todo = [i for i in range(ensemble.n) if i not in done]
    own_client = own_cluster = None
    if client is None:
        if scheduler is not None or scheduler_file is not None:
            client = own_client = connect(scheduler, timeout, scheduler_file=scheduler_file)
        else:
            own_cluster = local_cluster(workers)
            client = own_client = Client(own_cluster)
    register_single_thread(client)
    out.mkdir(parents=True, exist_ok=True)
    (out / DESCRIPTION).write_text(json.dumps({"sha256": digest, "description": ensemble.describe(),
                                               "samples": samples}, indent=1, default=repr))
    columns = _columns(ensemble)
    new = not table.exists()
    rows = []
    t0 = time.perf_counter()
    try:
        with table.open("a", newline="") as fh:
            if new:
                fh.write(_HEADER + digest + "\n")
            writer = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore")
            if new:
                writer.writeheader()
                fh.flush()
            if todo:
                futures = client.map(realize, [ensemble] * len(todo), todo, [samples[i] for i in todo], pure=False)
                index_of = {f.key: i for f, i in zip(futures, todo)}
                bar = None
                if progress and sys.stderr.isatty():
                    from tqdm import tqdm

                    bar = tqdm(total=len(todo), desc="realizations", unit="run")
                for fut in as_completed(futures):
                    try:
                        row = fut.result()
                    except Exception as exc:  # noqa: BLE001 - a worker that died (KilledWorker, lost)
                        i = index_of[fut.key]
                        row = {"index": i, "status": "crashed", "error": f"{type(exc).__name__}: {exc}",
                               **{f"p_{k}": v for k, v in samples[i].items()}}
                    png = row.pop("_picture", None)
                    if png:
                        pics = out / "realizations"
                        pics.mkdir(exist_ok=True)
                        (pics / f"{row['index']:05d}_failure.png").write_bytes(png)
                    writer.writerow(row)
                    fh.flush()
                    rows.append(row)
                    fut.release()
                    if bar is not None:
                        bar.update(1)
                        bar.set_postfix_str(f"#{row['index']} {row['status']} FoS {row.get('fos', math.nan):.3f}")
                if bar is not None:
                    bar.close()
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()
    return EnsembleRun(table, len(todo), len(done), time.perf_counter() - t0, rows)
