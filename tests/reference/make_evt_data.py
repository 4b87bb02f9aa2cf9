"""Write the seeded EVT data sets of tests/data/evt/ (inputs of make_evd_fixtures.R).

Run from the repository root: ``python tests/reference/make_evt_data.py``. Values are written with
12 significant digits; Python and R read the same decimal strings, so both fit identical doubles.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import stats

OUT = Path(__file__).resolve().parents[1] / "data" / "evt"

# name: (model, true shape xi, scale, loc or threshold, n, seed). Shape convention xi > 0 heavy tail.
CASES = {
    "gpd_light": ("gpd", -0.3, 2.0, 0.0, 1000, 401),
    "gpd_exp": ("gpd", 0.0, 1.5, 0.0, 2000, 402),
    "gpd_heavy03": ("gpd", 0.3, 1.0, 2.0, 500, 403),
    "gpd_heavy07": ("gpd", 0.7, 0.5, 0.0, 300, 404),
    "gpd_neg06": ("gpd", -0.6, 3.0, 1.0, 5000, 405),
    "gev_light": ("gev", -0.3, 0.5, 1.0, 200, 411),
    "gev_gumbel": ("gev", 0.0, 1.0, 0.0, 500, 412),
    "gev_heavy": ("gev", 0.3, 0.2, 0.5, 300, 413),
}


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    for name, (model, xi, scale, loc, n, seed) in CASES.items():
        rng = np.random.default_rng(seed)
        if model == "gpd":
            x = loc + stats.genpareto.rvs(xi, scale=scale, size=n, random_state=rng)
        else:
            x = stats.genextreme.rvs(-xi, loc=loc, scale=scale, size=n, random_state=rng)
        np.savetxt(OUT / f"{name}.csv", x, fmt="%.12g", header="x", comments="")


if __name__ == "__main__":
    main()
