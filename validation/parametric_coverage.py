r"""Share of simulated campaigns whose parametric bounds (Kannemans 2006) lie at or above the truth.

Usage::

    python validation/parametric_coverage.py [--reps 200] [--hours 6.5] [--first-seed 0]
        [--tau-pl 600] [--tau-ratio 300] [--out FILE.json]

Each repetition builds one 1 Hz station whose law is exactly the paper's model, so the truth is known:

* ratios: vertical :math:`r_V = m + \sigma_V z_t`, horizontal :math:`r_H = \sigma_H\sqrt{x_t^2 + y_t^2}`
  with :math:`z, x, y` independent AR(1) (first-order Gauss-Markov) series of 1/e time ``TAU_RATIO_S``;
* protection levels: Weibull marginals through a Gaussian copula,
  :math:`PL_t = (-\ln(1-\Phi(w_t))/a)^{1/b}`, :math:`w` AR(1) of 1/e time ``TAU_PL_S``,
  independent of the ratios (the paper's premise);
* errors: :math:`VPE = r_V\,VPL`, :math:`HPE = r_H\,HPL`.

and runs :func:`overbound.methods.parametric.parametric_analysis` with its defaults (automatic
decorrelation, confidence 0.95). Truth: :math:`P_{MI} = P(|r| > 1)`, the unavailability
:math:`\exp(-a\,AL^b)` and :math:`P_{HMI}` by :func:`~overbound.stats.parametric.integrity_probabilities`
at the true parameters. Prints and writes the share of repetitions with each bound at or above its
truth (documented: at least about the confidence, 0.95) with Clopper-Pearson intervals.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
import polars as pl
from evt_coverage import binomial_ci  # the same Clopper-Pearson share interval (same folder)
from scipy import special

from overbound.methods.parametric import parametric_analysis
from overbound.stats.parametric import RatioFit, WeibullFit, integrity_probabilities

TAU_RATIO_S = 300.0
TAU_PL_S = 600.0
MEAN_V, SIGMA_V, SIGMA_H = 0.02, 0.15, 0.12
#: Weibull (scale m, shape b) of VPL and HPL.
VPL_LAW, HPL_LAW = (20.0, 3.0), (15.0, 2.5)
#: (service, axis, AL) checked: unavailability from 0.37 down to 1e-5.
CHECKS = (("APV-II", "vertical", 20.0), ("LPV-200", "vertical", 35.0), ("APV-I", "horizontal", 40.0))


def _ar1(rng: np.random.Generator, n: int, tau_s: float) -> np.ndarray:
    """Unit-variance AR(1) at 1 s with 1/e time ``tau_s`` (stationary start), by a linear filter."""
    from scipy.signal import lfilter

    phi = math.exp(-1.0 / tau_s)
    e = rng.standard_normal(n) * math.sqrt(1.0 - phi * phi)
    e[0] = rng.standard_normal()
    return lfilter([1.0], [1.0, -phi], e)


def _weibull_pl(w: np.ndarray, scale: float, b: float) -> np.ndarray:
    return scale * (-special.log_ndtr(-w)) ** (1.0 / b)  # -ln(1 - Phi(w)) = -ln Phi(-w)


def campaign(
    seed: int, hours: float, tau_pl_s: float = TAU_PL_S, tau_ratio_s: float = TAU_RATIO_S
) -> pl.DataFrame:
    """One station of ``hours`` at 1 Hz from the model above."""
    rng = np.random.default_rng(seed)
    n = round(hours * 3600)
    rv = MEAN_V + SIGMA_V * _ar1(rng, n, tau_ratio_s)
    rh = SIGMA_H * np.hypot(_ar1(rng, n, tau_ratio_s), _ar1(rng, n, tau_ratio_s))
    vpl = _weibull_pl(_ar1(rng, n, tau_pl_s), *VPL_LAW)
    hpl = _weibull_pl(_ar1(rng, n, tau_pl_s), *HPL_LAW)
    t0 = np.datetime64("2026-01-01T00:00:00", "us")
    return pl.DataFrame(
        {
            "time": t0 + np.arange(n) * np.timedelta64(1, "s"),
            "station": ["SIM"] * n,
            "vpe": rv * vpl,
            "vpl": vpl,
            "hpe": rh * hpl,
            "hpl": hpl,
        }
    )


def truth() -> dict[str, dict[str, float]]:
    """True P_MI per axis and, per checked service, unavailability and P_HMI."""
    ratio = {
        "vertical": RatioFit("normal", MEAN_V, SIGMA_V, 0),
        "horizontal": RatioFit("rayleigh", SIGMA_H * math.sqrt(math.pi / 2.0), SIGMA_H, 0),
    }
    law = {"vertical": VPL_LAW, "horizontal": HPL_LAW}
    out: dict[str, dict[str, float]] = {}
    for name, axis, al in CHECKS:
        scale, b = law[axis]
        ip = integrity_probabilities(ratio[axis], WeibullFit(scale**-b, b, 0, True, 0), al)
        out[f"{axis}/{name}"] = {
            "log10_p_mi": ip.log10_p_mi,
            "log10_unavailability": ip.log10_unavailability,
            "log10_p_hmi": ip.log10_p_hmi,
        }
    return out


def one(seed: int, hours: float, tau_pl_s: float = TAU_PL_S, tau_ratio_s: float = TAU_RATIO_S) -> dict:
    a = parametric_analysis(
        campaign(seed, hours, tau_pl_s, tau_ratio_s), services=tuple(sorted({c[0] for c in CHECKS}))
    )
    row: dict = {"seed": seed}
    for name, axis, _ in CHECKS:
        ax = getattr(a, axis)
        s = ax.services[name]
        row[f"{axis}/{name}"] = {
            "log10_p_mi": ax.log10_p_mi,
            "log10_p_mi_bound": ax.log10_p_mi_bound,
            "log10_unavailability": s.log10_unavailability_fit,
            "log10_unavailability_bound": s.log10_unavailability_bound,
            "log10_p_hmi": s.log10_p_hmi,
            "log10_p_hmi_bound": s.log10_p_hmi_bound,
            "decorrelation_s": ax.decorrelation_s,
            "pl_decorrelation_s": ax.pl_decorrelation_s,
        }
    return row


def shares(rows: list[dict], true: dict) -> dict:
    """Per check and quantity: share of bounds >= truth (a missing bound counts as a miss), share of
    campaigns given no bound (too few effective samples: the method declines), share of false bounds
    (given and below the truth) and coverage among the bounds given; the median of log10(estimate/truth)."""
    out = {}
    for key, t in true.items():
        for q in ("p_mi", "unavailability", "p_hmi"):
            tv = t[f"log10_{q}"]
            b = np.array(
                [np.nan if (v := r[key][f"log10_{q}_bound"]) is None else v for r in rows], dtype=float
            )
            e = np.array([r[key][f"log10_{q}"] for r in rows], dtype=float)
            k = int(np.count_nonzero(b >= tv))
            given = int(np.count_nonzero(np.isfinite(b)))
            below = int(np.count_nonzero(b < tv))
            out[f"{key}/{q}"] = {
                "truth_log10": tv,
                "bound_at_or_above_truth": k / len(rows),
                "ci": binomial_ci(k, len(rows)),
                "no_bound": (len(rows) - given) / len(rows),
                "bound_below_truth": below / len(rows),
                "bound_below_truth_ci": binomial_ci(below, len(rows)),
                "coverage_of_bounds_given": k / given if given else None,
                "median_log10_estimate_over_truth": float(np.median(e - tv)),
            }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=200)
    ap.add_argument("--hours", type=float, default=6.5)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--tau-pl", type=float, default=TAU_PL_S, help="1/e time of the PL series (s)")
    ap.add_argument("--tau-ratio", type=float, default=TAU_RATIO_S, help="1/e time of the ratio series (s)")
    ap.add_argument("--out", default=None)
    o = ap.parse_args()
    t0 = time.perf_counter()
    rows = [one(s, o.hours, o.tau_pl, o.tau_ratio) for s in range(o.first_seed, o.first_seed + o.reps)]
    wall = time.perf_counter() - t0
    summary = {
        "config": {
            "reps": o.reps,
            "hours": o.hours,
            "first_seed": o.first_seed,
            "tau_ratio_s": o.tau_ratio,
            "tau_pl_s": o.tau_pl,
            "mean_v": MEAN_V,
            "sigma_v": SIGMA_V,
            "sigma_h": SIGMA_H,
            "vpl_weibull_scale_shape": VPL_LAW,
            "hpl_weibull_scale_shape": HPL_LAW,
        },
        "shares": shares(rows, truth()),
        "wall_s": round(wall, 1),
        "rows": rows,
    }
    print(f"{o.reps} campaigns of {o.hours:g} h at 1 Hz ({wall:.0f} s): share of bounds >= truth")
    for key, v in summary["shares"].items():
        lo, hi = v["ci"]
        print(
            f"  {key:36s} {v['bound_at_or_above_truth']:.3f} [{lo:.3f}, {hi:.3f}]"
            f"  no bound {v['no_bound']:.3f}, false bound {v['bound_below_truth']:.3f}"
            f"  truth 1e{v['truth_log10']:.2f}"
            f"  median log10(est/truth) {v['median_log10_estimate_over_truth']:+.2f}"
        )
    if o.out:
        with open(o.out, "w", encoding="utf-8") as f:
            json.dump(summary, f, indent=1)
            f.write("\n")


if __name__ == "__main__":
    main()
