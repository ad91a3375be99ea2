"""Ensemble results: the realizations table, failure probability with its Wilson interval,
rank correlations of the varied inputs with the factor of safety, and their plots."""
from __future__ import annotations

import json
import math
from pathlib import Path
import numpy as np
from fdem.io.ensemble_table import finite_number, DESCRIPTION, TABLE, read_table

__all__ = ["PARAMETER_UNITS", "parameter_label", "wilson_interval", "summarize", "fos_distribution_figure",
           "sensitivity_figure", "runout_figure"]


# ----------------------------------------------------------------------------- what it reports
def wilson_interval(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k/n`` (Wilson 1927):
    ``(p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)`` with ``z`` the two-sided
    normal quantile of ``confidence``. ``(nan, nan)`` for ``n = 0``."""
    from scipy.stats import norm

    if n == 0:
        return math.nan, math.nan
    z = float(norm.ppf(0.5 + confidence / 2))
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def _failed(row: dict) -> bool | None:
    """Whether a realization's FoS is below 1: ``None`` when not known (an error, or a bracket
    that straddles 1)."""
    st = row["status"]
    if st == "ok":
        return bool(row["fos"] < 1.0)
    if st in ("below_bracket", "above_bracket"):
        if row["fos_upper"] <= 1.0:
            return True
        if row["fos_lower"] >= 1.0:
            return False
    return None


def summarize(out, pictures: bool = True, confidence: float = 0.95) -> dict:
    """Statistics and plots of the table in ``out`` (written to ``<out>/summary.json``).

    * ``fos``: count, mean, sd, min, 5/50/95 % quantiles over ``ok`` realizations;
    * ``probability_of_failure``: ``P(FoS < 1) = k/m`` over the realizations whose FoS is
      known to lie below or above 1 (``ok``, and out-of-bracket ones whose bracket settles it),
      with the Wilson score interval at ``confidence`` and the Clopper-Pearson (exact) one;
    * ``spearman``: rank correlation ``rho`` (and its p-value) of the FoS with each sampled
      continuous parameter over ``ok`` realizations (``scipy.stats.spearmanr``);
    * ``runout``: distance and volume statistics where the runout was run;
    * plots: ``fos_distribution.png`` (histogram and empirical CDF with ``F = 1`` and ``P_f``),
      ``sensitivity.png`` (FoS against each parameter with ``rho``), ``runout_distribution.png``,
      and the failure pictures of the least and most stable realizations copied to
      ``least_stable.png`` / ``most_stable.png``.
    """
    from scipy import stats

    out = Path(out)
    _, rows = read_table(out / TABLE)
    ok = [r for r in rows if r["status"] == "ok"]
    fos = np.array([r["fos"] for r in ok])
    counts = {s: sum(r["status"] == s for r in rows) for s in ("ok", "below_bracket", "above_bracket", "error",
                                                                 "crashed")}
    known = [f for f in (_failed(r) for r in rows) if f is not None]
    k, m = int(sum(known)), len(known)
    pf = k / m if m else math.nan
    cp = stats.binomtest(k, m).proportion_ci(confidence, method="exact") if m else None
    params = [c[2:] for c in (rows[0] if rows else {}) if c.startswith("p_")]
    desc = json.loads((out / DESCRIPTION).read_text())["description"] if (out / DESCRIPTION).exists() else {}
    kinds = {name: v[0] for name, v in desc.get("parameters", {}).items()}
    varied = [p for p in params if kinds.get(p, "uniform") in ("uniform", "normal", "lognormal")]
    spearman = {}
    for p in varied:
        x = np.array([r[f"p_{p}"] for r in ok], dtype=float)
        if len(ok) >= 3 and np.ptp(x) > 0 and np.ptp(fos) > 0:
            res = stats.spearmanr(x, fos)
            spearman[p] = {"rho": float(res.statistic), "p_value": float(res.pvalue)}
        else:
            spearman[p] = {"rho": math.nan, "p_value": math.nan}
    wall = np.array([r["wall_s"] for r in rows if finite_number(r.get("wall_s"))])
    rss = np.array([r["peak_rss_mb"] for r in rows if finite_number(r.get("peak_rss_mb"))])
    run_d = np.array([r["runout_distance_m"] for r in rows if finite_number(r.get("runout_distance_m"))])
    run_v = np.array([r["runout_volume_m2"] for r in rows if finite_number(r.get("runout_volume_m2"))])

    def q(a, p):
        return float(np.quantile(a, p)) if a.size else math.nan

    summary = {
        "n_rows": len(rows), "status": counts,
        "fos": {"n": int(fos.size), "mean": float(fos.mean()) if fos.size else math.nan,
                "sd": float(fos.std(ddof=1)) if fos.size > 1 else math.nan, "min": q(fos, 0), "max": q(fos, 1),
                "p05": q(fos, 0.05), "p50": q(fos, 0.5), "p95": q(fos, 0.95)},
        "probability_of_failure": {"k": k, "m": m, "pf": pf, "confidence": confidence,
                                   "wilson": list(wilson_interval(k, m, confidence)),
                                   "clopper_pearson": [cp.low, cp.high] if cp else [math.nan, math.nan],
                                   "interval_reported": "wilson"},
        "spearman": spearman,
        "runout": {"n": int(run_d.size), "distance_p50_m": q(run_d, 0.5), "distance_p95_m": q(run_d, 0.95),
                   "volume_p50_m2": q(run_v, 0.5), "volume_p95_m2": q(run_v, 0.95)},
        "cost": {"wall_s_mean": float(wall.mean()) if wall.size else math.nan, "wall_s_max": q(wall, 1),
                 "peak_rss_mb_max": q(rss, 1)},
        "least_stable": int(ok[int(np.argmin(fos))]["index"]) if ok else None,
        "most_stable": int(ok[int(np.argmax(fos))]["index"]) if ok else None,
    }
    if pictures:
        summary["pictures"] = _plots(out, rows, ok, fos, varied, spearman, summary, run_d, run_v)
    from fdem.io.jsonable import write_json

    # undefined statistics (no realization with a FoS, an infinite upper bound) are JSON null
    write_json(out / "summary.json", summary, indent=1)
    return summary


PARAMETER_UNITS = {"cohesion": "Pa", "c": "Pa", "tensile_strength": "Pa", "f_t": "Pa", "friction_angle": "deg",
                   "phi": "deg", "dip": "deg", "dip_scatter": "deg", "trace_length": "m", "spacing": "m",
                   "size": "m", "height": "m", "joints": "-", "density": "kg/m^3", "young": "Pa", "poisson": "-",
                   "gravity_factor": "-", "reduction": "-"}
"""Units of the sampled parameters the scenes name, for the axis labels."""


def parameter_label(name: str) -> str:
    """``"name [unit]"`` from :data:`PARAMETER_UNITS`, or from a unit suffix of the name
    (``_m``, ``_pa``, ``_deg``, ``_s``); ``[as sampled]`` when the unit is not known."""
    unit = PARAMETER_UNITS.get(name)
    if unit is None:
        suffix = {"m": "m", "pa": "Pa", "deg": "deg", "s": "s", "kpa": "kPa", "mpa": "MPa"}
        unit = suffix.get(name.rpartition("_")[2].lower(), "as sampled") if "_" in name else "as sampled"
    return f"{name} [{unit}]"


def _figure(figsize):
    from fdem.io.pictures import new_figure

    return new_figure(figsize)


def fos_distribution_figure(fos: np.ndarray, summary: dict):
    """Histogram and empirical CDF of the factors of safety, ``F = 1`` and ``P_f`` marked."""
    fig = _figure((10, 3.8))
    a1, a2 = fig.subplots(1, 2)
    pf = summary["probability_of_failure"]
    if fos.size:
        a1.hist(fos, bins=max(5, int(math.sqrt(fos.size)) + 1), color="tab:blue", edgecolor="k")
        xs = np.sort(fos)
        a2.step(xs, np.arange(1, xs.size + 1) / xs.size, where="post", color="tab:blue", label="empirical CDF")
    for ax in (a1, a2):
        ax.axvline(1.0, color="tab:red", lw=1, label="FoS = 1")
        ax.set_xlabel("factor of safety [-]")
    a1.set_ylabel("realizations [-]")
    a2.set_ylabel("P(FoS <= x) [-]")
    lo, hi = pf["wilson"]
    a2.set_title(f"P(FoS < 1) = {pf['k']}/{pf['m']} = {pf['pf']:.3f}, "
                 f"{100 * pf['confidence']:.0f} % Wilson [{lo:.3f}, {hi:.3f}]", fontsize=9)
    a1.set_title(f"{fos.size} realizations with a FoS; {summary['status']['error']} errors, "
                 f"{summary['status']['below_bracket'] + summary['status']['above_bracket']} out of bracket",
                 fontsize=9)
    a2.legend(fontsize=8)
    fig.tight_layout()
    return fig


def sensitivity_figure(ok, fos: np.ndarray, varied, spearman):
    """The factor of safety against each varied parameter, with Spearman's rho."""
    fig = _figure((3.2 * len(varied), 3.2))
    axes = fig.subplots(1, len(varied), squeeze=False)
    for ax, p in zip(axes[0], varied):
        ax.plot([r[f"p_{p}"] for r in ok], fos, "o", ms=4)
        ax.axhline(1.0, color="tab:red", lw=1)
        ax.set_xlabel(parameter_label(p))
        ax.set_ylabel("factor of safety [-]")
        ax.set_title(f"Spearman rho = {spearman[p]['rho']:.2f}", fontsize=9)
    fig.tight_layout()
    return fig


def runout_figure(run_d: np.ndarray, run_v: np.ndarray):
    """Histograms of the runout distance and the displaced volume."""
    fig = _figure((9, 3.4))
    a1, a2 = fig.subplots(1, 2)
    a1.hist(run_d, bins=10, edgecolor="k")
    a1.set_xlabel("runout distance beyond the toe [m]")
    a2.hist(run_v, bins=10, edgecolor="k")
    a2.set_xlabel("displaced volume [m$^3$/m]")
    for ax in (a1, a2):
        ax.set_ylabel("realizations [-]")
    fig.tight_layout()
    return fig


def _plots(out: Path, rows, ok, fos, varied, spearman, summary, run_d, run_v) -> list[str]:
    import shutil

    written = []
    fos_distribution_figure(fos, summary).savefig(out / "fos_distribution.png", dpi=130)
    written.append("fos_distribution.png")
    if varied:
        sensitivity_figure(ok, fos, varied, spearman).savefig(out / "sensitivity.png", dpi=130)
        written.append("sensitivity.png")
    if run_d.size:
        runout_figure(run_d, run_v).savefig(out / "runout_distribution.png", dpi=130)
        written.append("runout_distribution.png")
    for key, name in (("least_stable", "least_stable.png"), ("most_stable", "most_stable.png")):
        i = summary[key]
        src = out / "realizations" / f"{i:05d}_failure.png" if i is not None else None
        if src is not None and src.exists():
            shutil.copyfile(src, out / name)
            written.append(name)
    return written
