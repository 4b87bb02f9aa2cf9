"""DO-229 SBAS user engine core: corrected ranges, variances, position errors and protection levels.

:func:`run_sbas` takes GPS L1 C/A pseudoranges (a RINEX observation table), the broadcast
ephemerides and the decoded SBAS messages of one GEO, and returns the epoch table of
:mod:`overbound.io.schema` and a per-satellite table with every correction and sigma term, the
post-fit residual and, for a satellite that was not used, why (``reason``).

Everything is computed per (epoch, satellite) row, vectorised over all rows at once: message
state is found by as-of look-ups (:mod:`overbound.sbas.corrections`), the grid ionosphere by
:mod:`overbound.sbas.iono`, the troposphere by :mod:`overbound.sbas.tropo`, the solution by a
batched weighted least squares (:mod:`overbound.sbas.solution`).

What is modelled (DO-229D appendix A and J; the time model is that of
:mod:`overbound.sbas.corrections`):

* fast corrections (MT 2-5, 24) with their UDREI, MT 6 integrity (IODF matching, alarm IODF 3),
  range-rate correction RRC from the last two PRCs of the satellite (A.4.4.3), applied as
  PRC + RRC (t - t_of); PRC time-out from the MT 7 indicator (Table A-8), RRC time-outs (the PRCs
  more than the smallest time-out of the mask apart, or propagated beyond 8 times their spacing);
  fast-correction history restarts after 4 or more missing messages and after a UDREI 14/15; with
  an alarm (IODF 3) in the current or previous fast correction the RRC takes the previous PRC with
  the largest spacing below I_fc / 2 (else the last one if within I_fc) and eps_rrc = (a_i |dt -
  I_fc / 2| / 2 + B_rrc / dt)(t - t_of) (A.4.4.3, A.4.5.1.2; no usable previous PRC: RRC 0, as gLAB);
* long-term corrections (MT 25, velocity codes 0 and 1) matched to the broadcast ephemeris by IODE
  (A.4.4.7); when the ephemeris of the newest IODE is not held (the SBAS changed IODE before the
  user has it), the last correction of the previous IODE, with that ephemeris, until it times out
  (Table A-25); the satellite clock's relativistic term per IS-GPS-200 20.3.3.3.3.1 (option
  ``relativity="rv"``: -2 r.v / c^2 as gLAB, up to 1.7 cm different in range);
* degradation (A.4.5.1): eps_fc = a_i (t - t_u + t_lat)^2 / 2, eps_rrc (0 for IODFs in sequence,
  else (a_i I_fc / 4 + B_rrc / dt) (t - t_of)), eps_ltc (velocity code 0:
  C_ltc_v0 floor((t - t_ltc) / I_ltc_v0); code 1: C_ltc_lsb + C_ltc_v1 max(0, t_0 - t, t - t_0 -
  I_ltc_v1) outside the validity interval), eps_er (below, NPA); sigma_flt with the MT 10 RSS_UDRE
  flag and delta-UDRE: MT 27 (A.4.4.13: complete IODS sets only, the highest-priority region holding
  the user, the smallest delta-UDRE_in among equal priorities, delta-UDRE_out outside all regions;
  triangles with the third corner (lat1, lon2), :data:`TRIANGLE_THIRD_CORNER`) or MT 28 (A.4.4.16,
  A.4.5.1.1: sqrt(I^T R^T R I) + C_covariance 2^(scale_exp - 5), I = [unit line of sight, 1]); 1 when
  neither or both are received;
* the grid ionosphere (cells chosen from the IGP mask alone, then four-point, three-point or no
  interpolation by the selected IGPs' state, A.4.4.10.2-3, :mod:`overbound.sbas.iono`) with
  sigma_UIVE from GIVE and eps_iono (C_iono_step floor((t - t_iono) /
  I_iono) + C_iono_ramp (t - t_iono), RSS_iono), sigma_UIRE = F_pp sigma_UIVE;
* MOPS troposphere and sigma_tropo; sigma_air of airborne accuracy designator A (DO-229D J.2.4:
  sigma_noise = 0.36 m, or 0.15 m for AAD-B, sigma_multipath = 0.13 + 0.53 exp(-E / 10 deg),
  sigma_divg = 0 for unsmoothed code), i.e. gLAB's class 2 receiver;
* PA (default) or NPA protection levels, elevation mask 5 deg.

Satellites are not used, with the first reason in this order: ``no_pseudorange``,
``messages_lost`` (4 or more consecutive missing messages at the epoch), ``no_mask``,
``mask_timeout``, ``not_in_mask``, ``no_mt10``, ``mt10_timeout``, ``no_fast_correction``,
``udre_timeout``, ``not_monitored`` (UDREI 14), ``do_not_use`` (UDREI 15), ``udrei_pa`` (UDREI >= 12
in PA), ``no_mt7``, ``mt7_timeout``, ``prc_timeout``, ``single_prc``, ``rrc_timeout``,
``rrc_propagation``, ``mt27_incomplete`` (MT 27 held, no complete IODS set), ``mt27_timeout``,
``no_mt28`` (MT 28 in use, none for this satellite), ``mt28_timeout``, ``no_long_term``,
``long_term_timeout``, ``no_ephemeris_iode``,
``elevation``, ``iono_mask_timeout``, ``no_igp_cell`` (no cell or triangle of IGPs in the mask),
``iono_outside_triangle`` (one IGP of the cell unusable and the pierce point outside the other
three), ``no_iono`` (other grid failures), ``too_few_satellites``.

NPA mode (``mode="NPA"``) differs from PA as DO-229D prescribes:

* HPL with K_H = 6.18 (J.1; VPL keeps K_V = 5.33 and is reported, not used for NPA);
* the NPA column of the time-outs: Table A-25 (MT 6/UDRE 18 s, MT 7 and MT 10 360 s, MT 25 360 s,
  the others as PA) and Table A-8 (fast corrections by MT 7 indicator, 18-180 s);
* the PA-only checks keep the satellite: 4 or more missing messages (``messages_lost``, 2.1.1.4.12)
  end PA only; without a usable MT 27 set or MT 28 delta-UDRE is 1; UDREI 12-13 (``udrei_pa``) are
  usable; without MT 10, or with MT 10 timed out,
  sigma_flt = (sigma_UDRE delta_UDRE + 8 m)^2 and the MT 10 degradation terms (eps_fc, eps_rrc,
  eps_ltc, eps_iono) are not applied (A.4.5.1);
* eps_er = C_er (MT 10) once the fast, the long-term or the MT 28 correction is older than its PA
  time-out but not its NPA one (A.4.5.1.4).

Where the grid gives no correction (``iono_mask_timeout``, ``no_igp_cell``,
``iono_outside_triangle``, ``no_iono``), NPA uses the GPS broadcast (Klobuchar) model of
IS-GPS-200 20.3.3.5.2.5 with sigma_UIRE^2 = max((T_iono / 5)^2, (F_pp tau_vert)^2) of DO-229D
J.2.3 (:mod:`overbound.sbas.klobuchar`; ``iono_mode`` :data:`IONO_MODE_KLOBUCHAR`), given the
navigation header's coefficients (``klobuchar=``; without them those rows keep their reason and
``counts["klobuchar"]`` is ``"no coefficients"``, else the number of rows used with it). PA never
does: it needs the grid.

gLAB's NPA differs in two ways. Its Klobuchar delay is a variant of IS-GPS-200's (spherical
pierce point, exact geomagnetic latitude, obliquity and cosine: up to 12 cm apart on the evening
Toulouse window; the sigmas agree except where the two geomagnetic latitudes fall on either side
of 55 deg). And without fast or long-term correction it uses the satellite with the MOPS-C sigma_flt
of 60 m and any broadcast IODE, which DO-229D does not have and this engine does not do. Elsewhere
the sigmas and PLs agree (tests/sbas/test_engine.py).

Not handled yet: GEO ranging, pierce points poleward of 75 deg, the previous-mask (old IODP/IODI)
fall-backs (MT 28 of the previous IODP included, which gLAB uses).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import polars as pl
import pymap3d

from overbound.io.rinex_nav import SPEED_OF_LIGHT, clock_at, ephemeris_elements, rotate_earth, state_at
from overbound.sbas import iono as ionomod
from overbound.sbas.corrections import (
    US,
    asof,
    earliest_within,
    packed_order,
    previous_other_value,
    previous_same_key,
    segments,
    times_us,
)
from overbound.sbas.klobuchar import geomagnetic_latitude, klobuchar_delay, klobuchar_sigma2
from overbound.sbas.messages import FC_TIMEOUT_NPA, FC_TIMEOUT_PA, SbasMessages
from overbound.sbas.solution import K_H_NPA, K_H_PA, K_V_PA, weighted_least_squares
from overbound.sbas.tropo import mapping, zenith_delays

__all__ = ["IONO_MODE_KLOBUCHAR", "REASONS", "SbasOptions", "SbasResult", "grid_iono_available", "run_sbas"]

C = SPEED_OF_LIGHT

#: Reasons for not using a satellite, in the order they are checked (0 = used).
REASONS = (
    "used", "no_pseudorange", "messages_lost", "no_mask", "mask_timeout", "not_in_mask", "no_mt10",
    "mt10_timeout", "no_fast_correction", "udre_timeout", "not_monitored", "do_not_use", "udrei_pa",
    "no_mt7", "mt7_timeout", "prc_timeout", "single_prc", "rrc_timeout", "rrc_propagation",
    "mt27_incomplete", "mt27_timeout", "no_mt28", "mt28_timeout",
    "no_long_term", "long_term_timeout", "no_ephemeris_iode", "elevation", "iono_mask_timeout", "no_igp_cell",
    "iono_outside_triangle", "no_iono", "too_few_satellites",
)  # fmt: skip

#: Message time-outs (s) for PA and NPA (DO-229D Table A-25), by message type.
TIMEOUT_PA = {1: 600, 6: 12, 7: 240, 10: 240, 18: 1200, 25: 240, 26: 600, 27: 86400, 28: 240}
TIMEOUT_NPA = {1: 600, 6: 18, 7: 360, 10: 360, 18: 1200, 25: 360, 26: 600, 27: 86400, 28: 360}
#: Third corner of an MT 27 triangle: "lat1_lon2" or "lat2_lon1". MT 27 broadcasts two corners per
#: region (DO-229D A.4.4.13, Table A-16); the four corners of a square are (lat1, lon1), (lat2, lon2),
#: (lat1, lon2), (lat2, lon1), and a triangle is the first three. gLAB v6 reads it so; the ICAO SARPs'
#: note to the service message (Annex 10 Vol. I App. B 3.5.4.9, coordinate 3 = coordinate 1 latitude,
#: coordinate 2 longitude; quoted from memory, the text was not at hand) agrees; MAAST takes
#: (lat2, lon1). EGNOS does not broadcast MT 27, so no data here exercise the choice;
#: tests/sbas/test_engine.py pins it.
TRIANGLE_THIRD_CORNER = "lat1_lon2"
#: ``iono_mode`` of a row whose ionosphere is the GPS broadcast model (NPA fall-back, DO-229D J.2.3); the
#: grid's codes are those of :class:`overbound.sbas.iono.GridSelection` (0 four points, 1-4 triangle,
#: -1 none).
IONO_MODE_KLOBUCHAR = 5
#: GPS broadcast ionospheric coefficients (alpha, beta), four each (IS-GPS-200 20.3.3.5.2.5).
Coefficients = tuple[Sequence[float], Sequence[float]]
#: Unix time (s) of the GPS epoch, 1980-01-06 00:00:00, for the GPS time of week.
_GPS_EPOCH_UNIX = 315_964_800
#: sigma_flt offset (m) when MT 10 is not held (DO-229D A.4.5.1: (sigma_UDRE delta_UDRE + 8 m)^2; NPA).
SIGMA_FLT_NO_MT10 = 8.0


@dataclass(frozen=True, slots=True)
class SbasOptions:
    """Engine options.

    Attributes
    ----------
    mode : ``"PA"`` or ``"NPA"`` (protection-level factors and time-outs).
    mask_deg : elevation mask.
    geo : PRN of the GEO whose messages are used (None: the only one present).
    flight_time : GEO signal flight time (s) added to message tags (gLAB's default 0.12 s).
    aad : airborne accuracy designator, ``"A"`` (sigma_noise 0.36 m) or ``"B"`` (0.15 m).
    relativity : satellite clock's relativistic term: ``"kepler"``, F e sqrt(A) sin(E_k) of
        IS-GPS-200 20.3.3.3.3.1 (default; the model the SBAS corrections refer to), or ``"rv"``,
        -2 r.v / c^2 from the broadcast position and velocity, as gLAB computes it. The two differ
        by the orbit's harmonic perturbations, up to 1.7 cm in range on the EGNOS day.
    """

    mode: str = "PA"
    mask_deg: float = 5.0
    geo: int | None = None
    flight_time: float = 0.12
    aad: str = "A"
    relativity: str = "kepler"

    def __post_init__(self) -> None:
        if self.mode not in ("PA", "NPA"):
            raise ValueError(f"mode {self.mode!r}: expected PA or NPA")
        if self.aad not in ("A", "B"):
            raise ValueError(f"aad {self.aad!r}: expected A or B")
        if self.relativity not in ("kepler", "rv"):
            raise ValueError(f"relativity {self.relativity!r}: expected kepler or rv")


@dataclass(frozen=True, slots=True)
class SbasResult:
    """``epochs``: the epoch table (overbound.io.schema); ``satellites``: one row per observation."""

    epochs: pl.DataFrame
    satellites: pl.DataFrame
    counts: dict[str, object] = field(default_factory=dict)


def run_sbas(
    obs: pl.DataFrame,
    eph: pl.DataFrame,
    msgs: SbasMessages,
    reference_ecef: tuple[float, float, float],
    *,
    station: str = "",
    options: SbasOptions | None = None,
    klobuchar: Coefficients | None = None,
    points: bool = False,
) -> SbasResult:
    """Process every epoch of ``obs`` (RINEX table with ``time``, ``system``, ``prn``, ``C1C``).

    ``eph`` is :attr:`overbound.io.rinex_nav.GpsEphemerides.table`; the linearisation point,
    elevation and pierce points use ``reference_ecef`` (the errors are against it too).
    ``klobuchar``: the GPS broadcast ionospheric coefficients (alpha, beta) of the navigation
    header (:class:`overbound.io.rinex_nav.NavHeader`), used in NPA where the grid gives no
    correction (DO-229D J.2.3); None: no fall-back, and ``counts["klobuchar"]`` says so.

    ``points``: many virtual receivers at once (the service-volume maps of
    :mod:`overbound.sbas.maps`): ``reference_ecef`` is then an (n, 3) array, ``obs`` has a ``point``
    column (row of ``reference_ecef``) and is sorted by time, point and PRN; an epoch is a (time,
    point) pair, and the epoch table gains the ``point`` column. Every row is computed by the same
    code as for one receiver, with that row's receiver position.
    """
    opt = options or SbasOptions()
    obs = obs.filter(pl.col("system") == "G")
    t = times_us(obs["time"])
    prn = obs["prn"].to_numpy().astype(np.int64)
    if not points and not _in_order(t, prn):  # a RINEX table usually is: no sort
        obs = obs.sort("time", "prn")
        t = times_us(obs["time"])
        prn = obs["prn"].to_numpy().astype(np.int64)
    pr = obs["C1C"].to_numpy().astype(float)
    point = obs["point"].to_numpy().astype(np.int64) if points else None
    if point is not None and not _in_order(t, point, prn):
        raise ValueError("run_sbas(points=True): rows must be sorted by time, point and PRN")
    new_epoch = np.ones(t.size, bool)  # rows are sorted by time: an epoch starts where t changes
    new_epoch[1:] = t[1:] != t[:-1]
    if point is not None:  # (or, for many receivers, where the point changes)
        new_epoch[1:] |= point[1:] != point[:-1]
    epochs_us, epoch = t[new_epoch], np.cumsum(new_epoch) - 1
    m = _select_geo(msgs, opt.geo)
    where = _Where.of(np.asarray(reference_ecef, float), point, new_epoch)
    del new_epoch
    lat, lon = where.lat, where.lon
    ctx = _Context(t=t, prn=prn, opt=opt, base=int(min(t.min(), times_us(m.log["time"]).min())) - 10**12,
                   epoch=epoch, epochs_us=epochs_us)  # fmt: skip
    reason = np.zeros(t.size, np.int16)

    def flag(cond: np.ndarray, name: str) -> None:
        reason[(reason == 0) & cond] = REASONS.index(name)

    pa = opt.mode == "PA"
    flag(~np.isfinite(pr), "no_pseudorange")
    # What depends on the time and the satellite only (messages in force, fast and long-term
    # corrections) is computed once per (time, PRN) and gathered to the rows: with many points (the
    # maps) the same satellite is a row of every point. Element by element the same arithmetic.
    sat, rows = _satellite_rows(ctx) if point is not None else (ctx, None)
    state = _satellite_state(sat, m, eph, pa)
    if rows is not None:
        state = _gather(state, rows)
    for name, cond in state.pop("flags"):
        flag(cond, name)
    mask, no_mt10 = state.pop("mask"), state.pop("no_mt10")
    deg = _Degradation(m.degradation, state.pop("r10"))
    fast, ltc = state.pop("fast"), state.pop("ltc")
    del state
    du = _delta_udre(ctx, m, mask, where)
    for name, cond in du["flags"]:
        flag(cond & pa, name)
    del mask
    for name, cond in ltc.pop("flags"):
        flag(cond, name)
    geom = _geometry(ctx, eph, pr, ltc, where)
    del ltc["eph_row"]
    flag(geom.pop("row") < 0, "no_ephemeris_iode")
    cov_row = du.pop("cov_row")
    dudre = np.where(cov_row >= 0, _covariance_delta(m.covariance, cov_row, geom.pop("los"),
                                                      deg["ccovariance"]), du.pop("value"))  # fmt: skip
    del cov_row
    # the range model's first terms, in the order of the sum below (the clock terms are not needed after)
    model = geom["rho"] - C * geom.pop("clock") + C * geom.pop("tgd")
    flag(geom["elev"] < np.deg2rad(opt.mask_deg), "elevation")
    grid = _iono(ctx, m, geom, lat, lon, deg)
    broadcast = _klobuchar_fallback(ctx, geom, grid, where, klobuchar) if not pa else None
    keep = np.ones(t.size, bool) if broadcast is None else ~broadcast  # rows the fall-back saves
    flag(grid.pop("mask_timeout") & keep, "iono_mask_timeout")
    fail = grid.pop("fail")
    flag((fail == ionomod.FAIL_NO_CELL) & keep, "no_igp_cell")
    flag((fail == ionomod.FAIL_OUTSIDE) & keep, "iono_outside_triangle")
    flag(~grid.pop("ok") & keep, "no_iono")
    del fail, keep
    # the zenith delays change with the day only: per epoch, then per row (mops_tropo's numbers)
    z_hyd, z_wet = zenith_delays(where.lat_ep, where.h_ep, _day_of_year(epochs_us))
    m_tropo = mapping(geom["elev"])
    tropo, sig_tropo = (z_hyd + z_wet)[epoch] * m_tropo, 0.12 * m_tropo

    # --- variances (DO-229D A.4.5, J.2.4) ---------------------------------------------------------
    sigma_udre = np.sqrt(fast.pop("sigma2_udre"))
    s_udre = sigma_udre * dudre
    eps_fc = np.where(no_mt10, 0.0, fast.pop("eps_fc"))
    eps_rrc = np.where(no_mt10, 0.0, fast.pop("eps_rrc"))
    eps_er = _eps_er(ctx, fast, ltc, du, deg)
    eps = eps_fc + eps_rrc + ltc["eps_ltc"] + eps_er
    rss = deg["rss_udre"] > 0
    sig2_flt = np.where(rss, s_udre**2 + eps_fc**2 + eps_rrc**2 + ltc["eps_ltc"] ** 2 + eps_er**2,
                        (s_udre + eps) ** 2)  # fmt: skip
    sig2_flt = np.where(no_mt10, (s_udre + SIGMA_FLT_NO_MT10) ** 2, sig2_flt)  # A.4.5.1, NPA only
    del s_udre, eps, rss
    elev_deg = np.rad2deg(geom["elev"])
    s_noise = 0.36 if opt.aad == "A" else 0.15
    s_mp = 0.13 + 0.53 * np.exp(-elev_deg / 10.0)
    sig2_air = s_noise**2 + s_mp**2
    sig2 = sig2_flt + grid["sigma2_uire"] + sig2_air + sig_tropo**2

    # --- corrected range and solution ----------------------------------------------------------------
    model += grid["slant"]
    model += tropo
    prefit = pr + fast["prc"] + fast["rrc_corr"] - model
    del model
    used = reason == 0
    k_h = K_H_PA if pa else K_H_NPA
    sol = weighted_least_squares(epoch, epochs_us.size, geom["elev"], geom["azim"], prefit, sig2, used,
                                 k_h=k_h, k_v=K_V_PA)  # fmt: skip
    too_few = used & (sol.nsv[epoch] == 0)
    reason[too_few] = REASONS.index("too_few_satellites")
    east, north, up = sol.enu[:, 0], sol.enu[:, 1], sol.enu[:, 2]
    epochs = pl.DataFrame(
        {
            "time": pl.Series(epochs_us.view("datetime64[us]")),
            **({"point": where.point_ep} if points else {}),
            "station": pl.Series([station] * epochs_us.size, dtype=pl.Categorical),
            "hpe": np.hypot(east, north),
            "vpe": up,
            "hpl": sol.hpl,
            "vpl": sol.vpl,
            "east": east,
            "north": north,
            "nsv": sol.nsv,
            "mode": pl.Series([opt.mode] * epochs_us.size, dtype=pl.Categorical),
        }
    )
    sats = pl.DataFrame(
        {
            "time": obs["time"],
            **({"point": obs["point"]} if points else {}),
            "prn": obs["prn"],
            "used": used & ~too_few,
            "reason": pl.Series(REASONS, dtype=pl.String).gather(reason.astype(np.int64)),
            "elevation": elev_deg,
            "azimuth": np.rad2deg(geom["azim"]),
            "pseudorange": pr,
            "prc": fast["prc"],
            "rrc": fast["rrc"],
            "rrc_corr": fast["rrc_corr"],
            "udrei": fast["udrei"],
            "sigma_udre": sigma_udre,
            "delta_udre": dudre,
            "ai": fast["ai"],
            "eps_fc": eps_fc,
            "eps_rrc": eps_rrc,
            "eps_ltc": ltc["eps_ltc"],
            "eps_er": eps_er,
            "sigma_flt": np.sqrt(sig2_flt),
            "iode": ltc["iode"],
            "previous_iode": ltc["previous_iode"],
            "ltc_dx": ltc["dx"], "ltc_dy": ltc["dy"], "ltc_dz": ltc["dz"], "ltc_clock": C * ltc["daf0_t"],
            "ipp_lat": grid["ipp_lat"], "ipp_lon": grid["ipp_lon"], "iono_mode": grid["mode"],
            "obliquity": grid["fpp"],
            "iono": grid["slant"],
            "sigma_uire": np.sqrt(grid["sigma2_uire"]),
            "tropo": tropo,
            "sigma_tropo": sig_tropo,
            "sigma_air": np.sqrt(sig2_air),
            "sigma": np.sqrt(sig2),
            "rho": geom["rho"],
            "prefit": prefit,
            "residual": sol.residual,
        }
    )  # fmt: skip
    n_by = np.bincount(reason, minlength=len(REASONS))
    counts = {"epochs": int(epochs_us.size), "rows": int(t.size),
              "reasons": {REASONS[i]: int(n_by[i]) for i in sorted(np.flatnonzero(n_by).tolist(),
                                                                    key=REASONS.__getitem__)}}  # fmt: skip
    if not pa:
        n_klob = "no coefficients" if broadcast is None else int((broadcast & (reason == 0)).sum())
        counts["klobuchar"] = n_klob
    return SbasResult(epochs=epochs, satellites=sats, counts=counts)


def _satellite_state(ctx: _Context, m: SbasMessages, eph: pl.DataFrame, pa: bool) -> dict:
    """The messages in force and the corrections of each row's satellite at its time: ``flags`` (in
    :func:`run_sbas`'s order of precedence, up to the fast corrections'), ``mask``, ``no_mt10``, ``r10``
    (the MT 10 row in force, -1 for none), ``fast`` and ``ltc`` (its own ``flags``, which come after
    delta-UDRE's)."""
    flags = []
    seg_epoch, lost = _message_loss(ctx, m)
    flags.append(("messages_lost", lost & pa))  # DO-229D 2.1.1.4.12: 4 lost messages end PA/APV only
    mask = _mask_state(ctx, m)
    flags += mask.flags
    mt10 = _latest(ctx, m.degradation, 10)
    mt10_out = (mt10 >= 0) & ctx.timed_out(m.degradation, mt10, 10)
    flags += [("no_mt10", (mt10 < 0) & pa), ("mt10_timeout", mt10_out & pa)]
    no_mt10 = (mt10 < 0) | mt10_out  # NPA only from here on: sigma_flt with the 8 m term, no degradation
    r10 = np.where(no_mt10, -1, mt10)  # NaN (absent terms) and the fill of no MT 10 read as 0
    deg = _Degradation(m.degradation, r10)
    del mt10, mt10_out
    # Intermediates are dropped (del, pop) once consumed: a day at 1 Hz is ~850,000 rows, 6.8 MB per
    # float column, and the peak memory is what is alive when the geometry and the grid are computed.
    fast = _fast(ctx, m, mask, seg_epoch, deg)
    del seg_epoch, lost
    flags += fast.pop("flags")
    ltc = _long_term(ctx, m, mask, deg, eph)
    return {"flags": flags, "mask": mask, "no_mt10": no_mt10, "r10": r10, "fast": fast, "ltc": ltc}


def _satellite_rows(ctx: _Context) -> tuple[_Context, np.ndarray]:
    """A context of the distinct (time, PRN) pairs of ``ctx``'s rows, and each row's pair."""
    key = (ctx.t - ctx.t.min()) * 256 + ctx.prn
    first, rows = np.unique(key, return_index=True, return_inverse=True)[1:]
    t, prn = ctx.t[first], ctx.prn[first]
    epochs_us, epoch = _distinct_times(t, np.arange(t.size))
    return _Context(t=t, prn=prn, opt=ctx.opt, base=ctx.base, epoch=epoch, epochs_us=epochs_us), rows


def _gather(value, rows: np.ndarray):
    """``value`` with every per-row array taken at ``rows`` (through dicts, lists, pairs and the mask)."""
    if isinstance(value, np.ndarray):
        return value[rows]
    if isinstance(value, dict):
        return {k: _gather(v, rows) for k, v in value.items()}
    if isinstance(value, list):
        return [_gather(v, rows) for v in value]
    if isinstance(value, tuple):
        return tuple(_gather(v, rows) for v in value)
    if isinstance(value, _Mask):
        return _Mask(*(_gather(getattr(value, f), rows) for f in _Mask.__slots__))
    return value


def grid_iono_available(
    msgs: SbasMessages,
    epochs_us: np.ndarray,
    lat: np.ndarray,
    lon: np.ndarray,
    options: SbasOptions | None = None,
) -> np.ndarray:
    """Whether the grid gives an ionospheric correction at pierce points ``lat``, ``lon`` ((p,) deg) at
    GPS times ``epochs_us`` ((t,), increasing), (t, p): the IGP cell selection and interpolation of
    :func:`run_sbas` (MT 18 mask and its time-out, MT 26 values and time-outs, A.4.4.10) for a pierce
    point at the place itself (a satellite at the zenith). The fast and long-term corrections, the PRN
    mask and the lost-message rule play no part (the ionospheric availability of gLAB's SBAS maps,
    whose node is the pierce point)."""
    opt = options or SbasOptions()
    shape = (np.size(epochs_us), np.size(lat))
    t = np.repeat(np.asarray(epochs_us, np.int64), shape[1])  # time-major: the epochs increase
    la, lo = np.tile(np.asarray(lat, float), shape[0]), np.tile(np.asarray(lon, float), shape[0])
    m = _select_geo(msgs, opt.geo)
    base = int(min(t.min(), times_us(m.log["time"]).min())) - 10**12
    n = t.size
    ctx = _Context(t=t, prn=np.ones(n, np.int64), opt=opt, base=base, epoch=np.arange(n), epochs_us=t)
    mt10 = _latest(ctx, m.degradation, 10)
    no_mt10 = (mt10 < 0) | ((mt10 >= 0) & ctx.timed_out(m.degradation, mt10, 10))
    deg = _Degradation(m.degradation, np.where(no_mt10, -1, mt10))
    geom = {"elev": np.full(t.size, np.pi / 2), "azim": np.zeros(t.size)}
    grid = _iono(ctx, m, geom, la, lo, deg)
    return (grid["ok"] & ~grid["mask_timeout"]).reshape(shape)


# --------------------------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class _Where:
    """The receiver of each row: ECEF ``rx`` and geodetic ``lat``, ``lon`` (deg), ``h`` (m), and ``lat_ep``,
    ``h_ep`` per epoch. Scalars (``rx`` (3,)) for one receiver, so that its numbers are those of a scalar
    computation; per-row arrays (``rx`` (n, 3)) for many (``point_ep``: each epoch's point)."""

    rx: np.ndarray
    lat: float | np.ndarray
    lon: float | np.ndarray
    h: float | np.ndarray
    lat_ep: float | np.ndarray
    h_ep: float | np.ndarray
    point_ep: np.ndarray | None = None
    point_row: np.ndarray | None = None  # each row's point, and the points' latitudes and longitudes
    point_lat: np.ndarray | None = None
    point_lon: np.ndarray | None = None

    @staticmethod
    def of(reference: np.ndarray, point: np.ndarray | None, new_epoch: np.ndarray) -> _Where:
        if point is None:
            lat, lon, h = (float(v) for v in pymap3d.ecef2geodetic(*reference))
            return _Where(reference, lat, lon, h, lat, h)
        plat, plon, ph = (np.asarray(v, float) for v in pymap3d.ecef2geodetic(*reference.T))
        point_ep = point[new_epoch]
        return _Where(reference[point], plat[point], plon[point], ph[point], plat[point_ep], ph[point_ep],
                      point_ep, point, plat, plon)  # fmt: skip

    @property
    def many(self) -> bool:
        return self.rx.ndim == 2

    def at(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``rx``, ``lat``, ``lon``, ``h`` of ``rows`` (the scalars themselves for one receiver)."""
        if not self.many:
            return self.rx, self.lat, self.lon, self.h  # type: ignore[return-value]
        return self.rx[rows], self.lat[rows], self.lon[rows], self.h[rows]  # type: ignore[index]


@dataclass(slots=True)
class _Context:
    t: np.ndarray  # epoch time per row (us)
    prn: np.ndarray
    opt: SbasOptions
    base: int
    epoch: np.ndarray  # epoch index per row
    epochs_us: np.ndarray  # time of each epoch (us)
    t_avail: np.ndarray = field(init=False)  # latest tag usable at each row's epoch: tag + flight <= t
    ep_avail: np.ndarray = field(init=False)  # the same per epoch

    def __post_init__(self) -> None:
        flight = round(self.opt.flight_time * US)
        self.t_avail = self.t - flight
        self.ep_avail = self.epochs_us - flight

    def timeout(self, mt: int) -> float:
        return (TIMEOUT_PA if self.opt.mode == "PA" else TIMEOUT_NPA)[mt]

    def age(self, tag_us: np.ndarray) -> np.ndarray:
        """t - (tag + flight) in seconds."""
        return (self.t - tag_us) / US - self.opt.flight_time

    def timed_out(self, table: pl.DataFrame, rows: np.ndarray, mt: int) -> np.ndarray:
        return self.age(_take(times_us(table["time"]), rows, fill=0)) > self.timeout(mt)


def _take(values: np.ndarray, rows: np.ndarray, fill: float = np.nan) -> np.ndarray:
    """``values[rows]`` with ``fill`` where rows is -1 (the "none" of every look-up here; rows >= -1).

    Integers and booleans come out as float with a float ``fill``, else as int64, so that differences and
    fills do not wrap. One gather from the table with ``fill`` appended (:func:`_with_fill`).
    """
    return _with_fill(values, fill)[rows]


def _with_fill(values: np.ndarray, fill: float = np.nan) -> np.ndarray:
    """``values`` with ``fill`` appended, so that row -1 picks it, in the dtype :func:`_take` gives."""
    values = np.asarray(values)
    if values.dtype.kind in "iub" or values.size == 0:
        dtype = np.dtype(float if isinstance(fill, float) else np.int64)
    else:
        dtype = values.dtype
    out = np.empty(values.size + 1, dtype)
    out[:-1] = values
    out[-1] = fill
    return out


def _in_order(*keys: np.ndarray) -> bool:
    """Whether the rows are strictly in the order of ``keys`` (e.g. time, PRN: the order a sort on them
    gives, ties excluded)."""
    ahead = np.zeros(max(keys[0].size - 1, 0), bool)  # decided: the row is after the previous one
    tied = ~ahead  # equal on the keys so far
    for k in keys:
        d = k[1:] - k[:-1]
        ahead |= tied & (d > 0)
        tied &= d == 0
    return bool(ahead.all())


def _ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a / b, 0 where b is 0 (an MT 10 interval that is absent: its degradation term is 0)."""
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    return np.divide(a, b, out=np.zeros(a.shape), where=b != 0)


def _select_geo(msgs: SbasMessages, geo: int | None) -> SbasMessages:
    geos = msgs.log["geo"].unique().to_list()
    if geo is None:
        if len(geos) != 1:
            raise ValueError(f"messages of several GEOs ({sorted(geos)}): choose one with geo=")
        return msgs
    if geo not in geos:
        raise ValueError(f"no messages of GEO {geo} (present: {sorted(geos)})")
    tables = {k: v.filter(pl.col("geo") == geo) for k, v in msgs.tables().items()}
    return SbasMessages(**tables, counts=msgs.counts)


def _latest(ctx: _Context, table: pl.DataFrame, mt: int, key: np.ndarray | None = None,
            key_tab: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """Last row of ``table`` available at each epoch (per key when given)."""
    tt = times_us(table["time"])
    if key is None:  # the same for every row of an epoch: searched per epoch
        zero = np.zeros(tt.size, np.int64)
        return asof(zero, tt, np.zeros(ctx.ep_avail.size, np.int64), ctx.ep_avail, ctx.base)[ctx.epoch]
    kt = np.zeros(tt.size, np.int64) if key_tab is None else key_tab
    return asof(kt, tt, key, ctx.t_avail, ctx.base)


def _message_loss(ctx: _Context, m: SbasMessages) -> tuple[np.ndarray, np.ndarray]:
    """Segment of the last message at each epoch, and whether 4+ messages are missing there."""
    log = m.log.filter(pl.col("crc_ok"))
    tags = times_us(log["time"])
    last = _latest(ctx, log, 0)
    seg = np.where(last >= 0, segments(tags)[np.maximum(last, 0)], -1)
    age = np.floor(ctx.age(_take(tags, last, fill=0)))
    return seg, (last < 0) | (age >= 4)


@dataclass(slots=True)
class _Mask:
    iodp: np.ndarray
    position: np.ndarray
    n_sats: np.ndarray
    flags: list


def _mask_state(ctx: _Context, m: SbasMessages) -> _Mask:
    """PRN mask (MT 1) in force and each satellite's position in it."""
    msg_t = m.mask["time"].unique(maintain_order=True)
    msg_tab = pl.DataFrame({"time": msg_t})
    row = _latest(ctx, msg_tab, 1)
    t_mask = _take(times_us(msg_t), row, fill=0)
    gps = m.mask.filter(pl.col("system") == "GPS")
    # a satellite is in the mask in force if the latest message holds it: its GPS row per (message, PRN),
    # the last one in table order, with a last row of none for "no message"
    msg_us = times_us(msg_t)
    sorter = np.argsort(msg_us)
    msg_of_row = sorter[np.searchsorted(msg_us, times_us(gps["time"]), sorter=sorter)]
    sv = gps["sv"].to_numpy().astype(np.int64)
    width = max(int(sv.max(initial=0)), int(ctx.prn.max(initial=0))) + 1
    rows_by_msg = np.full((msg_us.size + 1, width), -1, np.int64)
    np.maximum.at(rows_by_msg, (msg_of_row, sv), np.arange(sv.size))
    r = rows_by_msg.ravel()[np.where(row >= 0, row, msg_us.size) * width + ctx.prn]
    in_mask = r >= 0
    n_per_msg = m.mask.group_by("time", maintain_order=True).len()["len"].to_numpy()
    flags = [
        ("no_mask", row < 0),
        ("mask_timeout", (row >= 0) & (ctx.age(t_mask) > ctx.timeout(1))),
        ("not_in_mask", (row >= 0) & ~in_mask),
    ]
    return _Mask(
        iodp=np.where(in_mask, _take(gps["iodp"].to_numpy(), r, fill=0), -1),
        position=np.where(in_mask, _take(gps["position"].to_numpy(), r, fill=0), 0),
        n_sats=_take(n_per_msg, row, fill=0),
        flags=flags,
    )


def _segment_of(tags: np.ndarray, m: SbasMessages) -> np.ndarray:
    log_t = times_us(m.log.filter(pl.col("crc_ok"))["time"])
    seg = segments(log_t)
    return seg[np.clip(np.searchsorted(log_t, tags, side="right") - 1, 0, None)]


def _fast(ctx: _Context, m: SbasMessages, mask: _Mask, seg_epoch: np.ndarray, deg: _Degradation) -> dict:
    """Fast corrections, RRC, UDRE and their degradation (DO-229D A.4.4.3-5, A.4.5.1)."""
    pa = ctx.opt.mode == "PA"
    f = m.fast
    tf = times_us(f["time"])
    fkey = (_segment_of(tf, m) * 4 + f["iodp"].to_numpy()) * 64 + f["position"].to_numpy()
    qkey = (seg_epoch * 4 + mask.iodp) * 64 + mask.position
    fsort = packed_order(fkey, tf, ctx.base)  # the table is large: sorted once for its three look-ups
    r = asof(fkey, tf, qkey, ctx.t_avail, ctx.base, packed=fsort)
    r = np.where(mask.iodp >= 0, r, -1)
    prev = _take(previous_same_key(fkey, tf, ctx.base, packed=fsort), r, fill=-1)
    udrei_f = _take(f["udrei"].to_numpy(), r, fill=-1)
    tf_0 = _with_fill(tf, 0)
    tag_f = tf_0[r]
    iodf_tab = f["iodf"].to_numpy()
    iodf_f = _take(iodf_tab, r, fill=-1)
    # MT 6: the latest one, if newer than the fast correction and its IODF matches (or is 3)
    i6 = m.integrity
    t6 = times_us(i6["time"])
    r6 = asof(_segment_of(t6, m) * 64 + i6["position"].to_numpy(), t6, seg_epoch * 64 + mask.position,
              ctx.t_avail, ctx.base)  # fmt: skip
    tag6 = _take(t6, r6, fill=0)
    iodf6 = _take(i6["iodf"].to_numpy(), r6, fill=-1)
    newer6 = (r6 >= 0) & (r >= 0) & (tag6 > tag_f)
    match6 = newer6 & ((iodf6 == 3) | (iodf6 == iodf_f))
    udrei = np.where(match6, _take(i6["udrei"].to_numpy(), r6, fill=-1), udrei_f)
    t_udre = np.where(newer6, tag6, tag_f)
    t_u = np.where(match6, tag6, tag_f)  # also the PRC time (gLAB's reading of A.4.4.4)
    sigma2_udre = np.where(udrei >= 0, np.asarray(_SIGMA2_UDRE)[np.clip(udrei, 0, 15).astype(int)], np.nan)
    # MT 7
    f7 = m.fc_degradation
    t7 = times_us(f7["time"])
    r7 = asof(f7["iodp"].to_numpy() * 64 + f7["position"].to_numpy(), t7, mask.iodp * 64 + mask.position,
              ctx.t_avail, ctx.base)  # fmt: skip
    ai_index = _take(f7["ai_index"].to_numpy(), r7, fill=0)
    ai = _take(f7["ai"].to_numpy(), r7)
    tlat = _take(f7["tlat"].to_numpy(), r7)
    fc_tmout = np.asarray(FC_TIMEOUT_PA if pa else FC_TIMEOUT_NPA, float)
    tmout = fc_tmout[ai_index]
    tmin = _smallest_timeout(f7, r7, mask.n_sats, fc_tmout)
    # RRC from the last two PRCs; with an alarm (IODF 3) in the current or previous one, from the
    # previous PRC closest to I_fc / 2 before the current one (DO-229D A.4.4.3, A.4.5.1.2)
    iodf_9 = _with_fill(iodf_tab, -9)
    alarm = (iodf_f == 3) | (newer6 & (iodf6 == 3)) | (iodf_9[prev] == 3)
    prev_a = prev  # the search: only when some row has an alarm
    if alarm.any():
        prev_a = earliest_within(fkey, tf, np.where(alarm, r, -1), tmin * US / 2, ctx.base, packed=fsort)
    dt_prev = (tag_f - tf_0[prev]) / US
    prev_a = np.where(prev_a >= 0, prev_a, np.where(dt_prev <= tmin, prev, -1))
    prev = np.where(alarm, prev_a, prev)
    prc_tab = _with_fill(f["prc"].to_numpy())
    prc, prc_prev = prc_tab[r], prc_tab[prev]
    dt = (tag_f - tf_0[prev]) / US
    have2 = (prev >= 0) & (_take(f["udrei"].to_numpy(), prev, fill=15) < 14)
    t_of = (ctx.t - tag_f) / US + 1.0  # t - t_of, t_of = tag - 1 s
    rrc = np.where(have2 & (ai > 0), (prc - prc_prev) / np.where(dt > 0, dt, np.nan), 0.0)
    in_seq = np.mod(iodf_f - iodf_9[prev], 3) == 1
    brrc_dt = np.divide(deg["brrc"], dt, out=np.full(dt.shape, np.inf), where=dt > 0)
    off_half = np.abs(dt - tmin / 2)
    eps_rrc = np.where(alarm, np.where(off_half == 0, 0.0, (ai * off_half / 2 + brrc_dt) * t_of),
                       np.where(in_seq, 0.0, (ai * tmin / 4 + brrc_dt) * t_of))  # fmt: skip
    eps_rrc = np.where((ai == 0) | ~have2, 0.0, eps_rrc)
    eps_fc = ai * ((ctx.t - t_u) / US + 1.0 + tlat) ** 2 / 2
    no_fc = r < 0
    flags = [
        ("no_fast_correction", no_fc),
        ("udre_timeout", ~no_fc & (ctx.age(t_udre) > ctx.timeout(6))),
        ("not_monitored", ~no_fc & (udrei == 14)),
        ("do_not_use", ~no_fc & (udrei == 15)),
        ("udrei_pa", ~no_fc & pa & (udrei >= 12) & (udrei < 14)),
        ("no_mt7", r7 < 0),
        ("mt7_timeout", (r7 >= 0) & ctx.timed_out(f7, r7, 7)),
        ("prc_timeout", ctx.age(t_u) > tmout),
        ("single_prc", ~have2 & ~alarm),  # an alarm without a usable previous PRC: RRC 0
        ("rrc_timeout", have2 & (dt > tmin)),
        ("rrc_propagation", have2 & ((ctx.t - tag_f) / US > 8 * dt)),
    ]
    return {
        "prc": np.where(no_fc, np.nan, prc), "rrc": rrc, "rrc_corr": rrc * t_of, "udrei": udrei,
        "sigma2_udre": sigma2_udre, "ai": ai, "eps_fc": eps_fc, "eps_rrc": eps_rrc, "flags": flags,
        "pa_timed_out": ctx.age(t_u) > np.asarray(FC_TIMEOUT_PA, float)[ai_index],
    }  # fmt: skip


def _eps_er(ctx: _Context, fast: dict, ltc: dict, du: dict, deg: _Degradation) -> np.ndarray:
    """En-route degradation eps_er (DO-229D A.4.5.1.4): C_er (MT 10) in NPA once the fast, the
    long-term or the MT 28 correction has outlived its PA/APV time-out (Table A-8, A-25; for MT 28
    gLAB compares with the MT 25 one, the same 240 s) but not its NPA one; 0 in PA, where such a
    satellite is not used."""
    if ctx.opt.mode == "PA":
        return np.zeros(ctx.t.size)
    return np.where(fast["pa_timed_out"] | ltc["pa_timed_out"] | du["pa_timed_out"], deg["cer"], 0.0)


class _Degradation:
    """The MT 10 parameters in force per row, gathered when asked for (``deg[name]``, a new (n,) array).

    NaN (absent terms) and rows without MT 10 (``rows`` -1) read as 0. Sixteen parameters held as
    full columns would be ~110 MB for a day at 1 Hz, alive through the whole engine; the tables
    are a few hundred rows.
    """

    def __init__(self, table: pl.DataFrame, rows: np.ndarray) -> None:
        self._values = {c: np.nan_to_num(_with_fill(table[c].to_numpy().astype(float)))
                        for c in table.columns[2:]}  # fmt: skip
        self._rows = rows

    def __getitem__(self, name: str) -> np.ndarray:
        return self._values[name][self._rows]

    def at(self, name: str, rows: np.ndarray) -> np.ndarray:
        """``self[name][rows]`` without the full column."""
        return self._values[name][self._rows[rows]]


def _smallest_timeout(
    f7: pl.DataFrame, r7: np.ndarray, n_sats: np.ndarray, fc_tmout: np.ndarray
) -> np.ndarray:
    """Smallest fast-correction time-out over the satellites of the mask, from the same MT 7."""
    if f7.height == 0:
        return np.full(r7.shape, np.nan)
    tm = fc_tmout[f7["ai_index"].to_numpy().astype(int)].reshape(-1, 51)
    cummin = np.minimum.accumulate(tm, axis=1)
    msg = np.maximum(r7, 0) // 51
    return np.where(r7 >= 0, cummin[msg, np.clip(n_sats - 1, 0, 50)], np.nan)


_SIGMA2_UDRE = (
    0.0520, 0.0924, 0.1444, 0.2830, 0.4678, 0.8315, 1.2992, 1.8709,
    2.5465, 3.3260, 5.1968, 20.7870, 230.9661, 2078.695, np.nan, np.nan,
)  # fmt: skip


def _delta_udre(ctx: _Context, m: SbasMessages, mask: _Mask, where: _Where) -> dict:
    """delta-UDRE sources (DO-229D A.4.4.13, A.4.4.16): the MT 27 value at the user, or the MT 28 row.

    Only one of MT 27 and MT 28 is broadcast by an SBAS; with both held, or neither, delta-UDRE is 1
    (as gLAB). The MT 28 value needs the line of sight and is completed by :func:`_covariance_delta`.
    Flags (PA only): ``mt27_incomplete`` (no complete IODS set), ``mt27_timeout``, ``no_mt28`` (MT 28
    in use but none for this satellite in the mask in force), ``mt28_timeout``.
    """
    n = ctx.t.size
    s, cov = m.service, m.covariance
    r27 = _latest(ctx, s, 27) if s.height else np.full(n, -1)
    any28 = _latest(ctx, cov, 28) >= 0 if cov.height else np.zeros(n, bool)
    use27 = (r27 >= 0) & ~any28
    value = np.ones(n)
    flags: list = []
    if s.height:
        if where.many:  # the MT 27 region holding each receiver: the sets per point
            v_set, t_set = _service_sets(s, m.service_regions, where.point_lat, where.point_lon,
                                         needed=np.unique(r27[r27 >= 0]))  # fmt: skip
            v = np.concatenate([v_set, np.full((v_set.shape[0], 1), np.nan)], axis=1)[where.point_row, r27]
        else:
            v_set, t_set = _service_sets(s, m.service_regions, where.lat, where.lon)
            v = _take(v_set, r27)
        t_old = _take(t_set, r27, fill=0)
        incomplete = use27 & ~np.isfinite(v)
        timed_out = use27 & ~incomplete & (ctx.age(t_old) > ctx.timeout(27))
        value = np.where(use27 & ~incomplete & ~timed_out, v, 1.0)
        flags += [("mt27_incomplete", incomplete), ("mt27_timeout", timed_out)]
    row = np.full(n, -1)
    pa_timed_out = np.zeros(n, bool)
    if cov.height:
        tc = times_us(cov["time"])
        key = cov["iodp"].to_numpy().astype(np.int64) * 64 + cov["position"].to_numpy()
        r28 = asof(key, tc, mask.iodp * 64 + mask.position, ctx.t_avail, ctx.base)
        r28 = np.where(any28 & (r27 < 0) & (mask.iodp >= 0), r28, -1)
        age = ctx.age(_take(tc, r28, fill=0))
        timed_out = (r28 >= 0) & (age > ctx.timeout(28))
        flags += [("no_mt28", any28 & (r27 < 0) & (mask.iodp >= 0) & (r28 < 0)), ("mt28_timeout", timed_out)]
        row = np.where(timed_out, -1, r28)
        pa_timed_out = (row >= 0) & (age > TIMEOUT_PA[25])  # gLAB's eps_er test for MT 28 (NPA)
    return {"value": value, "cov_row": row, "pa_timed_out": pa_timed_out, "flags": flags}


def _service_sets(
    s: pl.DataFrame,
    regions: pl.DataFrame,
    lat: float | np.ndarray,
    lon: float | np.ndarray,
    needed: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """After each MT 27, the delta-UDRE at each user (``lat``, ``lon``: (u,) deg) from the newest complete
    IODS set, (u, messages) ((messages,) for one user given as scalars), and the time of that set's oldest
    message (NaN and 0 when no set is complete) (DO-229D A.4.4.13). ``needed``: the messages whose
    values are wanted (the others stay NaN): the sets are followed through every message, but the users'
    regions are evaluated for those only (a chunk of a map needs a few of a day's messages).

    A set is complete once messages 1..n_messages of one IODS are held; until a new IODS is complete the
    previous complete set stays in force. The user takes the region of highest priority code that
    contains it, the smallest delta-UDRE_in among equal priorities, and delta-UDRE_out outside all
    regions. Which set is in force does not depend on the user: found once, then evaluated for all users.
    """
    scalar = np.ndim(lat) == 0
    lat, lon = np.atleast_1d(np.asarray(lat, float)), np.atleast_1d(np.asarray(lon, float))
    st = times_us(s["time"])
    reg_t = times_us(regions["time"])
    cols = {c: s[c].to_numpy() for c in ("iods", "n_messages", "message_number", "priority")}
    din, dout = s["dudre_in"].to_numpy(), s["dudre_out"].to_numpy()
    wanted = np.ones(s.height, bool) if needed is None else np.isin(np.arange(s.height), needed)
    held: dict[int, dict[int, int]] = {}  # IODS -> message number -> row
    value = np.full((lat.size, s.height), np.nan)
    t_set = np.zeros(s.height, np.int64)
    current: tuple[tuple[int, ...], int, int] | None = None  # rows, oldest time, message completing it
    inside: dict[int, np.ndarray] = {}  # per message: which users its regions hold

    def inside_of(x: int) -> np.ndarray:
        if x not in inside:
            own = regions.filter(pl.Series(reg_t == st[x]))
            inside[x] = _in_regions(own, lat[:, None], lon[:, None]).any(axis=1)
        return inside[x]

    for k in range(s.height):
        iods = int(cols["iods"][k])
        held.setdefault(iods, {})[int(cols["message_number"][k])] = k
        rows = [held[iods].get(j) for j in range(1, int(cols["n_messages"][k]) + 1)]
        if all(x is not None for x in rows):
            current = (tuple(rows), int(st[np.asarray(rows)].min()), k)  # type: ignore[arg-type]
        if current is None:
            continue
        t_set[k] = current[1]
        if not wanted[k]:
            continue
        rows_a = np.asarray(current[0])
        hit = np.stack([inside_of(int(x)) for x in rows_a], axis=1)  # (users, set)
        pri = cols["priority"][rows_a].astype(np.int64)
        top = np.where(hit, pri, -1).max(axis=1)  # priority codes are 0-3
        best = hit & (pri == top[:, None])
        out = dout[current[2]]  # delta-UDRE_out of the message that completed the set
        value[:, k] = np.where(hit.any(axis=1), np.where(best, din[rows_a], np.inf).min(axis=1), out)
    return (value[0] if scalar else value), t_set


def _in_regions(regions: pl.DataFrame, lat: float, lon: float) -> np.ndarray:
    """Whether the user is inside each MT 27 region (boundary included).

    A square region spans the corners (lat1, lon1) and (lat2, lon2); a triangle is (lat1, lon1),
    (lat2, lon2) and the third corner :data:`TRIANGLE_THIRD_CORNER` (see there). Longitudes are
    taken as given (no region across the antimeridian).
    """
    la1, lo1 = regions["lat1"].to_numpy().astype(float), regions["lon1"].to_numpy().astype(float)
    la2, lo2 = regions["lat2"].to_numpy().astype(float), regions["lon2"].to_numpy().astype(float)
    square = regions["square"].to_numpy().astype(bool)
    in_box = ((np.minimum(la1, la2) <= lat) & (lat <= np.maximum(la1, la2))
              & (np.minimum(lo1, lo2) <= lon) & (lon <= np.maximum(lo1, lo2)))  # fmt: skip
    la3, lo3 = (la1, lo2) if TRIANGLE_THIRD_CORNER == "lat1_lon2" else (la2, lo1)

    def side(ax: np.ndarray, ay: np.ndarray, bx: np.ndarray, by: np.ndarray) -> np.ndarray:
        return (bx - ax) * (lat - ay) - (by - ay) * (lon - ax)

    d = np.stack([side(lo1, la1, lo2, la2), side(lo2, la2, lo3, la3), side(lo3, la3, lo1, la1)])
    in_tri = (d >= 0).all(axis=0) | (d <= 0).all(axis=0)
    return np.where(square, in_box, in_box & in_tri)


def _covariance_delta(cov: pl.DataFrame, row: np.ndarray, los: np.ndarray, ccov: np.ndarray) -> np.ndarray:
    """MT 28 delta-UDRE = sqrt(I^T C I) + eps_c (DO-229D A.4.5.1.1), NaN where ``row`` < 0.

    C = R^T R from the scaled Cholesky factor, I = [unit line of sight user->satellite, 1], eps_c =
    C_covariance 2^(scale_exp - 5) with ``ccov`` the MT 10 C_covariance (0 without MT 10).
    """
    out = np.full(row.size, np.nan)
    i = np.flatnonzero(row >= 0)
    if i.size == 0:
        return out
    e = {c: cov[c].to_numpy()[row[i]] for c in cov.columns if c.startswith("r")}
    z = np.zeros(i.size)
    rmat = np.stack([
        np.stack([e["r11"], e["r12"], e["r13"], e["r14"]], -1),
        np.stack([z, e["r22"], e["r23"], e["r24"]], -1),
        np.stack([z, z, e["r33"], e["r34"]], -1),
        np.stack([z, z, z, e["r44"]], -1),
    ], axis=1)  # fmt: skip
    vec = np.concatenate([los[i], np.ones((i.size, 1))], axis=1)
    ri = np.einsum("nij,nj->ni", rmat, vec)  # I^T R^T R I = |R I|^2
    scale = 2.0 ** (cov["scale_exp"].to_numpy()[row[i]].astype(float) - 5)
    out[i] = np.linalg.norm(ri, axis=1) + ccov[i] * scale
    return out


def _long_term(ctx: _Context, m: SbasMessages, mask: _Mask, deg: _Degradation, eph: pl.DataFrame) -> dict:
    """Long-term corrections (MT 25), their broadcast ephemeris and eps_ltc (DO-229D A.4.4.7, A.4.5.1.3).

    The correction applies to the ephemeris with the IODE it names (A.4.4.7). When the SBAS moves
    to a new IODE before the user holds that ephemeris (a merged daily file lacks the next day's
    records, a receiver may not have decoded it yet), the last correction of the previous IODE
    is used with the previous ephemeris until it times out (Table A-25: 240 s PA, 360 s NPA), as
    a user keeps one correction per IODE during the SBAS's IODE transition (the SBAS broadcasts
    both during the change-over). gLAB does the same.
    """
    lt = m.long_term
    tl = times_us(lt["time"])
    key = lt["iodp"].to_numpy().astype(np.int64) * 64 + lt["position"].to_numpy()
    iode_tab = lt["iode"].to_numpy().astype(np.int64)
    r = asof(key, tl, mask.iodp * 64 + mask.position, ctx.t_avail, ctx.base)
    r = np.where(mask.iodp >= 0, r, -1)
    timed_out = (r >= 0) & ctx.timed_out(lt, r, 25)
    iode_1 = _with_fill(iode_tab, -1)
    row_cur = _ephemeris_rows(ctx, eph, iode_1[r])
    prev = _take(previous_other_value(key, iode_tab, tl, ctx.base), r, fill=-1)
    prev = np.where((r >= 0) & ~timed_out & (row_cur < 0) & (prev >= 0), prev, -1)
    prev = np.where((prev >= 0) & ~ctx.timed_out(lt, prev, 25), prev, -1)
    row_prev = _ephemeris_rows(ctx, eph, iode_1[prev])
    use_prev = (prev >= 0) & (row_prev >= 0)
    r = np.where(use_prev, prev, r)
    names = ("dx", "dy", "dz", "daf0", "ddx", "ddy", "ddz", "daf1", "velocity_code")
    get = {c: _take(lt[c].to_numpy().astype(float), r) for c in names}
    t0 = _take(times_us(lt["t0"].fill_null(lt["time"])), r, fill=0)
    dt0 = np.where(get["velocity_code"] == 1, (ctx.t - t0) / US, 0.0)
    tag = _take(tl, r, fill=0)
    age_tx = (ctx.t - tag) / US + 1.0  # t - t_ltc, t_ltc = tag - 1 s
    v0 = deg["cltc_v0"] * np.floor(_ratio(age_tx, deg["iltc_v0"]))
    outside = np.maximum(0.0, np.maximum(-dt0, dt0 - deg["iltc_v1"]))
    v1 = np.where(outside > 0, deg["cltc_lsb"] + deg["cltc_v1"] * outside, 0.0)
    flags = [("no_long_term", r < 0), ("long_term_timeout", timed_out)]
    return {
        "pa_timed_out": (r >= 0) & (ctx.age(tag) > TIMEOUT_PA[25]),
        "iode": iode_1[r],
        "eph_row": np.where(use_prev, row_prev, row_cur),
        "previous_iode": use_prev,
        "dx": get["dx"] + get["ddx"] * dt0,
        "dy": get["dy"] + get["ddy"] * dt0,
        "dz": get["dz"] + get["ddz"] * dt0,
        "daf0_t": get["daf0"] + get["daf1"] * dt0,
        "eps_ltc": np.where(get["velocity_code"] == 1, v1, v0),
        "flags": flags,
    }  # fmt: skip


def _geometry(ctx: _Context, eph: pl.DataFrame, pr: np.ndarray, ltc: dict, where: _Where) -> dict:
    """Satellite position and clock at transmission (broadcast + long-term corrections), range,
    elevation and azimuth at the reference.

    The gathered broadcast elements (some 30 columns) are dropped before the per-row outputs are
    allocated, so that these reuse their memory.
    """
    n = ctx.t.size
    row = ltc["eph_row"]
    ok = (row >= 0) & np.isfinite(pr)
    i = np.flatnonzero(ok)
    if i.size == 0:
        return _geometry_out(n, row)
    tau0 = pr[i] / C
    el = ephemeris_elements(eph, row[i])  # gathered once for every evaluation below
    ti = ctx.t[i]
    tx = -tau0 - clock_at(el, ti, -tau0)  # transmission time offset from the epoch, s (receiver clock ~ 0
    del tau0
    st = state_at(el, ti, tx)  # is not assumed: the clock bias cancels in the solution's clock term)
    clock = st.clock
    if ctx.opt.relativity == "rv":  # -2 r.v / c^2 from the orbit itself (gLAB's choice)
        h = 1e-3
        vel = (state_at(el, ti, tx + h).position - state_at(el, ti, tx - h).position) / (2 * h)
        clock = clock - st.relativistic - 2.0 * np.sum(st.position * vel, axis=-1) / C**2
        del vel
    del el, ti, tx
    out = _geometry_out(n, row)
    out["clock"][i] = clock + ltc["daf0_t"][i]
    out["tgd"][i] = st.tgd
    pos = st.position + np.stack([ltc["dx"][i], ltc["dy"][i], ltc["dz"][i]], axis=-1)
    del st, clock
    # the light time from the position at transmission (one evaluation: the position does not change)
    rx, lat, lon, hgt = where.at(i)
    rot = rotate_earth(pos, _distance(pos, rx) / C)
    del pos
    d = [rot[:, k] - rx[..., k] for k in range(3)]  # receiver to satellite
    rho = np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    out["rho"][i] = rho
    for k in range(3):
        out["los"][i, k] = d[k] / rho
    del d, rho
    e, nn, u = pymap3d.ecef2enu(rot[:, 0], rot[:, 1], rot[:, 2], lat, lon, hgt)
    del rot
    out["elev"][i] = np.arctan2(u, np.hypot(e, nn))
    out["azim"][i] = np.arctan2(e, nn)
    return out


def _geometry_out(n: int, row: np.ndarray) -> dict:
    """:func:`_geometry`'s outputs for rows without a satellite position (``row``: the ephemeris rows)."""
    return {"row": row, "rho": np.full(n, np.nan), "clock": np.full(n, np.nan), "tgd": np.full(n, np.nan),
            "elev": np.full(n, -np.pi / 2), "azim": np.zeros(n), "los": np.full((n, 3), np.nan)}  # fmt: skip


def _distance(pos: np.ndarray, rx: np.ndarray) -> np.ndarray:
    """|pos - rx| per row of an (n, 3) array, by columns (no (n, 3) temporaries)."""
    d = [pos[:, k] - rx[..., k] for k in range(3)]
    return np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])


def _ephemeris_rows(ctx: _Context, eph: pl.DataFrame, iode: np.ndarray) -> np.ndarray:
    """Healthy broadcast record with the IODE of the long-term correction whose fit interval covers t.

    Unlike :func:`overbound.io.rinex_nav.select_ephemeris` the RINEX transmission time is not
    required to precede t: merged daily files carry the time a network first logged the record,
    often later than the SBAS started correcting that IODE (PRN 7, IODE 89 on the EGNOS day:
    corrected from 08:03, logged 08:43). gLAB does not check it either.
    """
    out = np.full(iode.size, -1, np.int64)
    q = np.flatnonzero(iode >= 0)  # only rows with a correction's IODE (few for the previous IODE)
    toe = times_us(eph["toe_time"])
    fit = eph["fit_interval"].to_numpy()
    half = (np.where(fit > 1, fit, 4.0) * 1800 * US).astype(np.int64)
    key = eph["prn"].to_numpy().astype(np.int64) * 1024 + eph["iode"].to_numpy().astype(np.int64)
    healthy = eph["health"].to_numpy() == 0
    t = ctx.t[q]
    r = asof(key[healthy], (toe - half)[healthy], ctx.prn[q] * 1024 + iode[q], t, ctx.base)
    r = _take(np.flatnonzero(healthy), r, fill=-1)
    fits = np.abs(t - _take(toe, r, fill=0)) <= _take(half, r, fill=0)
    out[q] = np.where((r >= 0) & fits, r, -1)
    return out


def _iono(ctx: _Context, m: SbasMessages, geom: dict, lat: float, lon: float, deg: _Degradation) -> dict:
    """Grid ionosphere: slant delay, sigma_UIRE^2 and the pierce point (DO-229D A.4.4.10)."""
    n = ctx.t.size
    lat_pp, lon_pp = ionomod.pierce_point(np.deg2rad(lat), np.deg2rad(lon), geom["elev"], geom["azim"])
    np.rad2deg(lat_pp, out=lat_pp)  # degrees from here on (the outputs and the cell selection)
    np.rad2deg(lon_pp, out=lon_pp)
    fpp = ionomod.obliquity(geom["elev"])
    mk = m.igp_mask
    # MT 18 in force per band, and its time-out
    band_key = mk["band"].to_numpy().astype(np.int64)
    tmk = times_us(mk["time"])
    # grid values: MT 26 rows placed on the globe through the mask of their band and IODI
    where = mk.select("band", "iodi", "igp", "lat", "lon").unique(("band", "iodi", "igp"), keep="last")
    g = m.iono.join(where, on=("band", "iodi", "igp"), how="inner").drop_nulls(("lat", "lon"))
    tg = times_us(g["time"])
    gkey = ionomod.igp_key(g["lat"].to_numpy(), g["lon"].to_numpy())
    sel = geom["elev"] > 0
    idx = np.flatnonzero(sel)
    flight_us = round(ctx.opt.flight_time * US)

    # The mask in force changes rarely: per epoch, the IODI of each band, and per distinct set of band
    # IODIs ("mask version") which 5-degree IGP positions are in the mask.
    mk_pos = mk.drop_nulls(("lat", "lon"))
    pos_key = ionomod.igp_key(mk_pos["lat"].to_numpy(), mk_pos["lon"].to_numpy())
    member = np.unique(_mask_code(mk_pos["band"].to_numpy(), mk_pos["iodi"].to_numpy(), pos_key))
    bands = np.unique(band_key)
    ep_t, ep = _distinct_times(ctx.epochs_us - flight_us, ctx.epoch)  # the same t_avail for every row of
    # an epoch (and of every point at that time: the mask and the grid values depend on the time only)
    # IODI per (band, epoch), -2 where no MT 18 of the band; a last row of -2 for bands not in the mask
    iodi_ep = np.full((bands.size + 1, ep_t.size), -2, np.int64)
    mk_sort = packed_order(band_key, tmk, ctx.base)  # one sort for the look-ups of every band
    for i_b, b in enumerate(bands.tolist()):
        iodi_ep[i_b] = _band_iodi(mk, band_key, tmk, np.full(ep_t.size, b, np.int64), ep_t, ctx.base,
                                  packed=mk_sort)  # fmt: skip
    change = np.ones(ep_t.size, bool)  # a new mask version where any band's IODI changes
    change[1:] = (iodi_ep[:, 1:] != iodi_ep[:, :-1]).any(axis=0)
    version_ep = np.cumsum(change) - 1
    versions = iodi_ep[:-1, change].T
    all_keys = np.arange(ionomod.N_IGP_KEYS, dtype=np.int64)
    in_version = np.zeros((versions.shape[0], ionomod.N_IGP_KEYS), bool)
    for v, iodis in enumerate(versions.tolist()):
        for b, iodi_b in zip(bands.tolist(), iodis, strict=True):
            if iodi_b >= 0:
                in_version[v] |= np.isin(_mask_code(b, iodi_b, all_keys), member)

    ep_idx = ep[idx]  # epoch of each pierce point

    def in_mask(rows: np.ndarray, key: np.ndarray) -> np.ndarray:
        return in_version.ravel()[(version_ep[ep_idx[rows]] * ionomod.N_IGP_KEYS)[:, None] + key]

    g_band = g["band"].to_numpy().astype(np.int64)
    pos_b = np.searchsorted(bands, g_band)  # row of iodi_ep of each grid value's band
    known = pos_b < bands.size
    known[known] = bands[pos_b[known]] == g_band[known]
    g_band_row = np.where(known, pos_b, bands.size)
    # per grid value, with a last "no value" row that index -1 (no MT 26 yet) picks: a gather per
    # look-up, no fill pass (the no-value row is never current: IODI -1 against the band's -2)
    tag_g = np.append(tg, 0)
    iodi_g = np.append(g["iodi"].to_numpy().astype(np.int64), -1)
    band_row_g = np.append(g_band_row, bands.size)
    give_g = np.append(np.isfinite(g["sigma2_give"].to_numpy()), False)
    dnu_g = np.append(g["givd_dnu"].to_numpy().astype(bool), False)
    # The grid value of each IGP at each epoch (the latest MT 26 available, as corrections.asof) and
    # whether it is current (its IODI that of its band's mask in force), tabulated once per "grid state":
    # the epochs between two changes of the MT 26 tags available or of the mask version.
    cells = _GridStates(gkey, tg, ep_t, version_ep)
    value = cells.table  # (states, IGPs) row of g, -1 for none
    cur = iodi_g[value] == iodi_ep[:, change][band_row_g[value], cells.version[:, None]]
    flags = (cur & give_g[value]).astype(np.int8) | ((cur & dnu_g[value]).astype(np.int8) << 1)
    state_ep = cells.state_ep
    # the time-out test of age = (t - tag) / US - flight <= timeout as tag >= t - d_max, the same
    # predicate (the float expression grows with the integer t - tag)
    d_max = _largest_age_us(ctx.timeout(26), ctx.opt.flight_time)
    found_r: dict[str, np.ndarray] = {}

    def status(rows: np.ndarray, key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cell = cells.cell(state_ep[ep_idx[rows]], key)
        r = value.ravel()[cell]
        found_r["rows"], found_r["r"] = rows, r  # kept for the interpolation below
        fl = flags.ravel()[cell]
        fresh = tag_g[r] >= (ctx.t[idx[rows]] - d_max)[:, None]
        return ((fl & 1) != 0) & fresh, (fl & 2) != 0

    sel = ionomod.select_and_interpolate(lat_pp[idx], lon_pp[idx], in_mask, status)
    ok_sub, w, mode_sub, fail_sub = sel.ok, sel.weights, sel.mode, sel.fail
    del sel  # the corner keys, (n, 4)
    # only pierce points with a cell can have a correction (ok_sub False elsewhere): the grid values
    # are those of status()'s look-up
    f, r = found_r.pop("rows", np.zeros(0, np.int64)), found_r.pop("r", np.zeros((0, 4), np.int64))
    vert, s2uive = np.zeros(idx.size), np.zeros(idx.size)
    vert[f], s2uive[f] = _grid_sums(ctx.t, idx[f], w[f], r, g, tag_g, deg)
    del f, r, w
    ok = np.zeros(n, bool)
    ok[idx] = ok_sub
    mode = np.full(n, -1)
    mode[idx] = mode_sub
    fail = np.zeros(n, np.int64)
    fail[idx] = fail_sub
    slant = np.full(n, np.nan)
    slant[idx] = np.where(ok_sub, fpp[idx] * vert, np.nan)
    s2uire = np.full(n, np.nan)
    s2uire[idx] = np.where(ok_sub, fpp[idx] ** 2 * s2uive, np.nan)
    # mask time-out: the latest MT 18 of any band older than its time-out
    last18 = _latest(ctx, mk, 18)
    mask_to = (last18 >= 0) & (ctx.age(_take(tmk, last18, fill=0)) > ctx.timeout(18))
    return {"ok": ok, "mode": mode, "fail": fail, "slant": slant, "sigma2_uire": s2uire, "fpp": fpp,
            "mask_timeout": mask_to,
            "ipp_lat": lat_pp, "ipp_lon": lon_pp}  # fmt: skip


def _distinct_times(ep_t: np.ndarray, epoch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct times of the sorted epoch times ``ep_t`` and each row's index into them (``epoch``: each
    row's epoch): with many points an epoch is a (time, point) pair, and per-time tables are P times
    smaller."""
    new = np.ones(ep_t.size, bool)
    new[1:] = ep_t[1:] != ep_t[:-1]
    if new.all():
        return ep_t, epoch
    return ep_t[new], (np.cumsum(new) - 1)[epoch]


def _grid_sums(t: np.ndarray, rows: np.ndarray, w: np.ndarray, r: np.ndarray, g: pl.DataFrame,
               tag_g: np.ndarray, deg: _Degradation) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Vertical delay and sigma_UIVE^2 at the pierce points ``rows`` from their corners' grid values (DO-229D
    A.4.4.10.3, A.4.5.2): sums over the corners of w GIVD and w sigma2_grid, sigma2_grid = sigma2_GIVE +
    eps_iono^2 (RSS_iono) or (sigma_GIVE + eps_iono)^2, eps_iono = C_iono_step floor((t - t_iono) / I_iono) +
    C_iono_ramp (t - t_iono), t_iono = tag - 1 s.

    ``w``: (m, 4) weights, ``r``: (m, 4) rows of ``g`` (-1 for none: a value of 0), ``tag_g`` their tags
    with a last entry for -1. Corner by corner on (m,) columns (no (m, 4) temporaries), summed from 0 in
    corner order: the numbers of ``(w * x).sum(axis=1)``, which adds four terms so, bit for bit.
    """
    givd_g = np.nan_to_num(np.append(g["givd"].to_numpy(), np.nan))
    s2give_g = np.nan_to_num(np.append(g["sigma2_give"].to_numpy(), np.nan))
    t_rows = t[rows]
    step, interval, ramp = deg.at("ciono_step", rows), deg.at("iiono", rows), deg.at("ciono_ramp", rows)
    rss = deg.at("rss_iono", rows) > 0
    vert, s2uive = np.zeros(rows.size), np.zeros(rows.size)
    for k in range(r.shape[1]):
        rk = r[:, k]
        t_iono = (t_rows - tag_g[rk]) / US + 1.0  # t - (tag - 1)
        eps = step * np.floor(_ratio(t_iono, interval)) + ramp * t_iono
        s2give = s2give_g[rk]
        s2grid = np.where(rss, s2give + eps**2, (np.sqrt(s2give) + eps) ** 2)
        vert += w[:, k] * givd_g[rk]
        s2uive += w[:, k] * s2grid
    return vert, s2uive


def _klobuchar_fallback(
    ctx: _Context, geom: dict, grid: dict, where: _Where, coefficients: Coefficients | None
) -> np.ndarray | None:
    """NPA: the GPS broadcast model where the grid gives no correction (DO-229D J.2.3), in ``grid``.

    The rows whose grid failed or whose IGP mask timed out, above the horizon, get the slant delay
    of IS-GPS-200 20.3.3.5.2.5, sigma_UIRE^2 = max((T_iono / 5)^2, (F_pp tau_vert)^2) and
    ``iono_mode`` :data:`IONO_MODE_KLOBUCHAR`; returns those rows, or None without coefficients.
    """
    if coefficients is None:
        return None
    alpha, beta = coefficients
    rows = (grid["mask_timeout"] | ~grid["ok"]) & (geom["elev"] > 0)
    i = np.flatnonzero(rows)
    _, lat, lon, _ = where.at(i)
    lat_r, lon_r = np.deg2rad(lat), np.deg2rad(lon)
    el, az = geom["elev"][i], geom["azim"][i]
    sow = np.mod(ctx.t[i] // US - _GPS_EPOCH_UNIX, 7 * 86_400).astype(float) + (ctx.t[i] % US) / US
    delay = klobuchar_delay(alpha, beta, lat_r, lon_r, el, az, sow)
    grid["slant"][i] = delay
    grid["sigma2_uire"][i] = klobuchar_sigma2(delay, el, geomagnetic_latitude(lat_r, lon_r, el, az))
    grid["mode"][i] = IONO_MODE_KLOBUCHAR
    return rows


def _mask_code(band: np.ndarray | int, iodi: np.ndarray, key: np.ndarray) -> np.ndarray:
    """One integer per (band, IODI, IGP position)."""
    return (np.asarray(band, np.int64) * 4 + np.asarray(iodi, np.int64)) * 4096 + np.asarray(key, np.int64)


class _GridStates:
    """The latest MT 26 row of each IGP per grid state (as :func:`overbound.sbas.corrections.asof`).

    A state is a run of epochs with the same MT 26 tags available (tag <= t_avail) and the same mask
    version. ``table`` is (states, IGPs + 1): the row of the grid values with the largest tag (the
    last in table order among equal tags) per IGP, -1 where none; the last column is for IGPs without
    any MT 26 value. ``state_ep``: each epoch's state; ``version``: each state's mask version.
    """

    def __init__(self, gkey: np.ndarray, tg: np.ndarray, ep_t: np.ndarray, version_ep: np.ndarray) -> None:
        keys, kcol = np.unique(gkey, return_inverse=True)
        self.column = np.full(ionomod.N_IGP_KEYS, keys.size, np.int64)  # grid key -> column
        self.column[keys] = np.arange(keys.size)
        rows = _rows_in_force(kcol, tg, int(ep_t.min()), int(ep_t.max())) if ep_t.size else np.arange(0)
        tags, tag_i = np.unique(tg[rows], return_inverse=True)
        n_avail = np.searchsorted(tags, ep_t, side="right")  # distinct tags available at each epoch
        by_tag = np.full((tags.size + 1, keys.size + 1), -1, np.int64)
        np.maximum.at(by_tag, (tag_i + 1, kcol[rows]), rows)  # largest row among equal tags
        # forward fill: the last tag count up to each one with a value of the IGP
        last = np.where(by_tag >= 0, np.arange(tags.size + 1)[:, None], 0)
        np.maximum.accumulate(last, axis=0, out=last)
        by_tag = np.take_along_axis(by_tag, last, axis=0)
        new = np.ones(ep_t.size, bool)
        new[1:] = (n_avail[1:] != n_avail[:-1]) | (version_ep[1:] != version_ep[:-1])
        self.state_ep = np.cumsum(new) - 1
        self.version = version_ep[new]
        self.table = by_tag[n_avail[new]]
        self.width = keys.size + 1

    def cell(self, state: np.ndarray, key: np.ndarray) -> np.ndarray:
        """Flat index into ``table`` of (state per row, grid keys (rows, k))."""
        return state[:, None] * self.width + self.column[key]


def _rows_in_force(kcol: np.ndarray, tg: np.ndarray, t0: int, t1: int) -> np.ndarray:
    """The rows of the grid values that can be the latest of their IGP at a time in [t0, t1], increasing:
    those tagged in (t0, t1] and, per IGP, the last of the latest tagged at or before t0 (the row that
    the table of :class:`_GridStates` keeps among equal tags). The table of a chunk of a few minutes
    then spans its own tags, not the whole day's (the same entries: the others are never the latest)."""
    old = np.flatnonzero(tg <= t0)
    order = old[np.lexsort((old, tg[old], kcol[old]))]  # by IGP, then tag, then row
    last = np.ones(order.size, bool)
    last[:-1] = kcol[order[1:]] != kcol[order[:-1]]
    return np.sort(np.concatenate([order[last], np.flatnonzero((tg > t0) & (tg <= t1))]))


def _largest_age_us(timeout: float, flight: float) -> int:
    """The largest integer d (us) with d / US - flight <= timeout in floating point (ages of integer tags)."""
    d = round((timeout + flight) * US)
    while d / US - flight > timeout:
        d -= 1
    while (d + 1) / US - flight <= timeout:
        d += 1
    return d


def _band_iodi(mk: pl.DataFrame, band_key: np.ndarray, tmk: np.ndarray, band_q: np.ndarray, t_q: np.ndarray,
               base: int, packed: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:  # fmt: skip
    """IODI of the latest MT 18 of each queried band (``packed``: :func:`packed_order` of the mask table)."""
    r = asof(band_key, tmk, band_q.ravel(), t_q.ravel(), base, packed=packed).reshape(band_q.shape)
    return _take(mk["iodi"].to_numpy(), r, fill=-2)


def _day_of_year(t_us: np.ndarray) -> np.ndarray:
    d = t_us.view("datetime64[us]").astype("datetime64[D]")
    return (d - d.astype("datetime64[Y]")).astype(np.int64) + 1
