r"""Seeded stochastic simulator of a 1 Hz SBAS receiver campaign with exactly known truth.

Every statistical method of overbound (PL confidence level per PL band, EVT
extrapolation of P(|PE| > PL), parametric normal/Rayleigh/Weibull fits) is tested
against this simulator: it writes the ordinary epoch table of
:mod:`overbound.io.schema` plus truth columns holding, per epoch, the exact
error distribution and the exact probability of misleading information.

Notes
-----
**Time grid.** Epochs :math:`t_k = k\,\Delta t`, :math:`k = 0 \dots N-1`, seconds after
``start`` (GPS time), :math:`N = \mathrm{round}(86400\,\mathrm{days}/\Delta t)`. All
processes run on the full grid; *gaps* then remove rows and *outages* blank them.

**Protection levels.** The vertical PL model sigma is

.. math::

    \sigma_v(t) = \sigma_{v0}\, \exp\big(g_v(t) + x(t) + A\cos(2\pi (h(t) - 14)/24)\big),
    \qquad \mathrm{VPL} = K_v\,\sigma_v,

1. *Geometry* :math:`g_v(t) = \sum_{j=1}^{6} a_j \sin(2\pi j t / T_s + \varphi_j)`, with the
   sidereal day :math:`T_s` = 86164.09 s and its harmonics :math:`T_s/2 \dots T_s/6` (the GPS
   constellation repeats once per sidereal day). Phases are uniform on
   :math:`[0, 2\pi)`; amplitudes are random weights scaled so that the time-averaged
   standard deviation of :math:`g_v` is exactly ``geometry_log_sd``
   (:math:`\sum a_j^2/2` = ``geometry_log_sd**2``).
2. *Satellite set events* :math:`x(t) = \sum_i J_i\, e^{-(t-\tau_i)/\tau_r}\,1[t \ge \tau_i]`:
   a Poisson process of rate ``set_rate_per_hour`` with exponential log-jumps
   :math:`J_i` of mean ``set_jump_mean`` that relax with time constant
   :math:`\tau_r` = ``set_relax_s``. It is computed exactly on the grid as a
   first-order IIR filter (``scipy.signal.lfilter``) of an impulse train, the impulse
   of event *i* at the first epoch :math:`k_i \ge \tau_i/\Delta t` having weight
   :math:`J_i e^{-(k_i\Delta t - \tau_i)/\tau_r}`. The sum is then saturated,
   :math:`x \leftarrow X\tanh(x/X)` with :math:`X` = ``set_log_max``, so that overlapping events
   cannot raise the PL by more than :math:`e^X`.
3. *Ionosphere*: a diurnal factor :math:`e^{A\cos(\cdot)}` peaking at 14:00 local solar
   time :math:`h = ` GPS hour of day + ``longitude_deg``/15, :math:`A` = ``iono_amplitude``.

The horizontal model sigma is :math:`\sigma_h = r\,\sigma_v\,e^{g_h(t)}`, ``HPL`` =
:math:`K_h\sigma_h`, with :math:`r` = ``h_to_v`` and :math:`g_h` a second, independent
six-harmonic sidereal sum of standard deviation ``h_geometry_log_sd``. PLs are always
> 0 and right skewed (log-normal-like body, set events give the heavy right tail).
With the defaults the median VPL is about 14 m (EGNOS-like), about 1.5 % of epochs
have VPL > 50 m (APV-I unavailable), fewer HPL > 40 m and none HPL > 556 m (NPA). ``nsv`` =
clip(rint(9 - 8 (g_v + x)), 6, 12) follows the geometry inversely (cosmetic, no
truth depends on it); ``mode`` is ``"PA"``.

**Position errors.**

.. math::

    \mathrm{VPE}_k = b_v(t_k) + s_v(t_k)\, m_v(t_k)\, z_v(t_k), \quad
    s_v = f\,\frac{\mathrm{VPL}}{K_v}\,\prod_{\text{bands}} F_{band},

    e_k = s_h m_h z_e, \quad n_k = b_h + s_h m_h z_n, \quad
    s_h = f\,\frac{\mathrm{HPL}}{K_h}\prod F_{band}, \quad \mathrm{HPE} = \sqrt{e^2 + n^2},

* :math:`f` = ``sigma_ratio``: the PL overbounds the error when :math:`f < 1`
  (:math:`f = 1` makes the PL exactly :math:`K\sigma`), and violates it when :math:`f > 1`.
* :math:`z_v, z_e, z_n`: independent unit-variance Gauss-Markov (AR(1)) processes,
  :math:`z_k = \phi z_{k-1} + \sqrt{1-\phi^2}\,w_k`, :math:`\phi = e^{-\Delta t/\tau_c}`,
  :math:`\tau_c` = ``correlation_s``, started in stationarity (:math:`z_{-1} \sim N(0,1)`), run
  with ``lfilter`` whose state is carried across chunks, so the output is independent
  of the chunk size. Autocorrelation at lag :math:`\tau_c` is :math:`e^{-1}`.
* :math:`m(t)`: the *regime* multiplier, ``tail_scale`` while the heavy-tail regime is on
  and 1 otherwise, applied to the axes named by ``tail_axis``. The regime is a
  continuous-time two-state Markov chain with mean tail dwell :math:`D_1` =
  ``tail_dwell_s`` and mean nominal dwell :math:`D_0 = D_1(1-\varepsilon)/\varepsilon`, so its
  stationary tail share is exactly :math:`\varepsilon` = ``tail_fraction``; it starts in
  stationarity (exponential sojourns are memoryless) and is sampled at the epochs.
* :math:`F_{band}`: ``band:LO:HI:FACTOR[:AXIS]`` anomalies multiply the error sigma of
  epochs whose PL of that axis lies in [LO, HI) m (the ENAC 15-16 m tail anomaly of
  Comby et al. 2003 is ``band:15:16:3``).
* :math:`b_v, b_h`: ``bias:START_H:DURATION_S:METRES[:AXIS[:RAMP_S]]`` anomalies, summed.
  Shape: a trapezoid starting START_H hours into the campaign, rising linearly over
  RAMP_S seconds to METRES, holding, and falling over the last RAMP_S seconds of
  DURATION_S; RAMP_S = 0 (the default) is a plain step, on for
  :math:`t \in [t_0, t_0 + D)`. A vertical bias is added to VPE, a horizontal bias to the
  north error (the horizontal truth depends only on its magnitude).

**Missing data.** *Gaps* (rows absent from the table) and *outages* (rows kept with
NaN ``hpe, vpe, hpl, vpl, east, north`` and NaN truth, null ``nsv`` and ``mode``) are
Poisson processes of ``gap_rate_per_day`` / ``outage_rate_per_day`` with
exponential durations of mean ``gap_mean_s`` / ``outage_mean_s``; an
``outage:START_H:DURATION_S`` anomaly forces one more. An epoch :math:`t_k` is in an
interval :math:`[s, e)` when :math:`s \le t_k < e`; a gap wins over an outage. The realised
intervals are recorded (:attr:`StationTruth.gaps`, :attr:`StationTruth.outages`).

**Truth columns** (NaN on outage rows):

* ``sigma_v_true``, ``sigma_h_true`` (m): :math:`s_v` and :math:`s_h` above, i.e. the 1-sigma of
  VPE and of *each* horizontal component in the **nominal regime**, band factors
  included. The marginal (regime-unconditional) error law of an epoch is the mixture
  :math:`(1-\varepsilon)N(b, s^2) + \varepsilon N(b, (c s)^2)`, :math:`c` = ``tail_scale``, on the
  axes of ``tail_axis``; its parameters are recorded in the metadata
  (:meth:`Simulation.truth_dict`). With ``tail_fraction = 0`` the law is
  :math:`N(b, s^2)` and ``vpe / sigma_v_true`` is exactly N(0, 1) when unbiased.
* ``regime`` (Int8): the realised regime state (0 nominal, 1 heavy tail), so that the
  regime-conditional sigma is ``sigma * tail_scale**regime`` on the regime axes. It is
  kept on outage rows (the hidden state runs on).
* ``bias_v_true`` (m), ``bias_h_true`` (m, north component): only when a bias
  anomaly is configured.
* ``p_mi_v_true`` = P(|VPE| > VPL) and ``p_mi_h_true`` = P(HPE > HPL), exact, marginal
  over the regime, conditional on the realised PL (PLs do not depend on the regime):

  .. math::

      P_v(L; s, b) = \bar\Phi\big(\tfrac{L-b}{s}\big) + \bar\Phi\big(\tfrac{L+b}{s}\big), \qquad
      P_h(L; s, b) = Q_{\chi'^2_2}\big(L^2/s^2;\ b^2/s^2\big)
      \ \big(= e^{-L^2/(2s^2)} \text{ for } b = 0\big),

      p = (1-\varepsilon)\,P(L; s, b) + \varepsilon\,P(L; c s, b),

  :math:`\bar\Phi(x)` = ``scipy.special.ndtr(-x)`` and :math:`Q_{\chi'^2_2}` =
  ``scipy.stats.ncx2.sf`` (the Rice distribution of HPE), both accurate down to
  ~1e-300 (:func:`p_exceed`).

**Campaign truth.** :meth:`Simulation.p_mi_true` is the mean of ``p_mi_*_true`` over
epochs with a solution, i.e. the expected empirical MI frequency;
:meth:`Simulation.p_mi_true_band` the same within a PL band;
:meth:`Simulation.p_hmi_true` the mean over epochs with PL < AL of
:math:`P(|PE| > AL)` from the same formula with :math:`L` = AL (``conditional=False`` divides
by all solution epochs instead: Kannemans 2006 eq. for :math:`P_{HMI}`, the joint
probability of PL < AL and PE > AL).

**Randomness and determinism.** One ``numpy.random.SeedSequence(seed)`` (one child
per station when ``stations > 1``, named ``SIM01``...) spawns independent streams
for geometry, set events, regime, gaps, outages, :math:`z_v`, :math:`z_e`, :math:`z_n`. Events are
drawn sequentially in fixed-size batches, so the same config gives the same bytes,
and a longer campaign with the same seed extends a shorter one epoch for epoch.

References
----------
.. [1] H. Kannemans, "An integrity, availability and continuity test method for
   EGNOS/WAAS", NLR-TP-2006-594 (ION GNSS 2006): VPE/VPL normal, HPE/HPL Rayleigh,
   PL Weibull; P_HMI double integral (section 2.1.3).
.. [2] Comby et al., EGNOS VPL assessment (ENAC, 2003): VPL confidence level per
   1 m VPL band, tail anomaly between 15 and 16 m.
.. [3] Veerman et al., GIMAT: EVT-based integrity tool; safety index XPE/XPL, MI vs HMI.
.. [4] RTCA DO-229E, J.2.1/J.2.2: K_V = 5.33, K_H,PA = 6.0.
"""

from __future__ import annotations

import datetime as dt
import json
import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, TypeAlias

import numpy as np
import polars as pl
from scipy import signal, special, stats

from overbound.io.table import read_epochs_metadata, write_epochs
from overbound.services import SERVICES

__all__ = [
    "SIDEREAL_DAY_S",
    "TRUTH_COLUMNS",
    "Anomaly",
    "BandAnomaly",
    "BiasAnomaly",
    "OutageAnomaly",
    "Simulation",
    "SimulationConfig",
    "StationTruth",
    "p_exceed",
    "parse_anomaly",
    "read_simulation",
    "simulate",
    "write_simulation",
]

#: Sidereal day (s): the GPS constellation geometry repeats with this period (approximately).
SIDEREAL_DAY_S = 86164.09
#: Harmonics of the sidereal day used by the geometry factor (periods T_s/j).
_HARMONICS = np.arange(1, 7)
#: Epochs per processing chunk; results do not depend on it (state is carried over).
_CHUNK = 1 << 17
#: Events drawn per batch; fixed so that a longer campaign extends a shorter one.
_BATCH = 1024
#: nsv = clip(rint(_NSV_MID - _NSV_SLOPE * log-geometry), _NSV_MIN, _NSV_MAX).
_NSV_MID, _NSV_SLOPE, _NSV_MIN, _NSV_MAX = 9.0, 8.0, 6, 12
_AXES = {"v": "vertical", "vertical": "vertical", "h": "horizontal", "horizontal": "horizontal"}
_TAIL_AXES = {**_AXES, "both": "both", "hv": "both", "vh": "both"}

#: Truth columns appended to the epoch table, with unit and meaning.
TRUTH_COLUMNS: dict[str, str] = {
    "sigma_v_true": "m; 1-sigma of VPE in the nominal regime (band factors included)",
    "sigma_h_true": "m; 1-sigma of each of east/north in the nominal regime (band factors included)",
    "bias_v_true": "m; deterministic VPE bias (only with a bias anomaly)",
    "bias_h_true": "m; deterministic north-error bias (only with a bias anomaly)",
    "p_mi_v_true": "-; exact P(|VPE| > VPL), marginal over the regime",
    "p_mi_h_true": "-; exact P(HPE > HPL), marginal over the regime",
    "regime": "-; realised error regime, 0 nominal, 1 heavy tail",
}


def _fmt(x: float) -> str:
    """Shortest round-tripping text of a float, without a trailing ``.0``."""
    s = repr(float(x))
    return s[:-2] if s.endswith(".0") else s


def _axis(axis: str) -> str:
    try:
        return _AXES[axis.lower()]
    except (KeyError, AttributeError):
        raise ValueError(f"axis {axis!r}: expected 'vertical' ('v') or 'horizontal' ('h')") from None


# --------------------------------------------------------------------------- anomalies


@dataclass(frozen=True, slots=True)
class BandAnomaly:
    """Error sigma times ``factor`` at epochs whose ``axis`` PL lies in [lo, hi) m.

    Spec ``band:LO:HI:FACTOR[:AXIS]``, AXIS ``v`` (default) or ``h``.
    """

    lo: float
    hi: float
    factor: float
    axis: str = "vertical"

    def __post_init__(self) -> None:
        object.__setattr__(self, "axis", _axis(self.axis))
        if not (math.isfinite(self.lo) and self.lo >= 0 and math.isfinite(self.hi) and self.hi > self.lo):
            raise ValueError(f"band anomaly: need 0 <= LO < HI (finite), got LO={self.lo}, HI={self.hi}")
        if not (math.isfinite(self.factor) and self.factor > 0):
            raise ValueError(f"band anomaly: FACTOR must be > 0, got {self.factor}")

    @property
    def spec(self) -> str:
        return f"band:{_fmt(self.lo)}:{_fmt(self.hi)}:{_fmt(self.factor)}:{self.axis[0]}"

    def __str__(self) -> str:
        return self.spec


@dataclass(frozen=True, slots=True)
class BiasAnomaly:
    """Deterministic error bias of ``metres`` from ``start_h`` hours for ``duration_s`` s.

    Spec ``bias:START_H:DURATION_S:METRES[:AXIS[:RAMP_S]]``: a trapezoid with linear
    ramps of ``ramp_s`` seconds at both ends (0, the default, is a plain step). A
    vertical bias adds to VPE, a horizontal one to the north error.
    """

    start_h: float
    duration_s: float
    metres: float
    axis: str = "vertical"
    ramp_s: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "axis", _axis(self.axis))
        if not (math.isfinite(self.start_h) and self.start_h >= 0):
            raise ValueError(f"bias anomaly: START_H must be >= 0, got {self.start_h}")
        if not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise ValueError(f"bias anomaly: DURATION_S must be > 0, got {self.duration_s}")
        if not math.isfinite(self.metres):
            raise ValueError(f"bias anomaly: METRES must be finite, got {self.metres}")
        if not (math.isfinite(self.ramp_s) and 0 <= self.ramp_s <= self.duration_s / 2):
            raise ValueError(f"bias anomaly: need 0 <= RAMP_S <= DURATION_S/2, got RAMP_S={self.ramp_s}")

    @property
    def spec(self) -> str:
        s = f"bias:{_fmt(self.start_h)}:{_fmt(self.duration_s)}:{_fmt(self.metres)}:{self.axis[0]}"
        return s + (f":{_fmt(self.ramp_s)}" if self.ramp_s else "")

    def __str__(self) -> str:
        return self.spec

    def value(self, t: np.ndarray) -> np.ndarray:
        """The bias (m) at campaign times ``t`` (s after start)."""
        t0 = self.start_h * 3600.0
        if self.ramp_s == 0:
            return np.where((t >= t0) & (t < t0 + self.duration_s), self.metres, 0.0)
        edge = np.minimum(t - t0, t0 + self.duration_s - t) / self.ramp_s
        return self.metres * np.clip(edge, 0.0, 1.0)


@dataclass(frozen=True, slots=True)
class OutageAnomaly:
    """A forced no-solution period. Spec ``outage:START_H:DURATION_S``."""

    start_h: float
    duration_s: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.start_h) and self.start_h >= 0):
            raise ValueError(f"outage anomaly: START_H must be >= 0, got {self.start_h}")
        if not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise ValueError(f"outage anomaly: DURATION_S must be > 0, got {self.duration_s}")

    @property
    def spec(self) -> str:
        return f"outage:{_fmt(self.start_h)}:{_fmt(self.duration_s)}"

    def __str__(self) -> str:
        return self.spec


Anomaly: TypeAlias = BandAnomaly | BiasAnomaly | OutageAnomaly

_SPECS = {
    "band": (BandAnomaly, ("LO", "HI", "FACTOR"), ("AXIS",)),
    "bias": (BiasAnomaly, ("START_H", "DURATION_S", "METRES"), ("AXIS", "RAMP_S")),
    "outage": (OutageAnomaly, ("START_H", "DURATION_S"), ()),
}


def parse_anomaly(text: str) -> Anomaly:
    """An anomaly from its command-line spec.

    Parameters
    ----------
    text
        ``band:LO:HI:FACTOR[:AXIS]``, ``bias:START_H:DURATION_S:METRES[:AXIS[:RAMP_S]]``
        or ``outage:START_H:DURATION_S``; AXIS is ``v`` (default) or ``h``.

    Returns
    -------
    BandAnomaly | BiasAnomaly | OutageAnomaly
        Its ``spec`` (and ``str``) gives back a canonical spec that parses to an equal object.

    Raises
    ------
    ValueError
        Unknown kind, wrong number of fields, a non-number, or an out-of-range value;
        the message quotes the spec and the expected form.

    Examples
    --------
    >>> parse_anomaly("band:15:16:3")
    BandAnomaly(lo=15.0, hi=16.0, factor=3.0, axis='vertical')
    >>> str(parse_anomaly("bias:2:600:4.5:h:60"))
    'bias:2:600:4.5:h:60'
    """
    if not isinstance(text, str):
        raise ValueError(f"anomaly spec must be a string, got {type(text).__name__}")
    parts = [p.strip() for p in text.strip().split(":")]
    kind = parts[0].lower()
    if kind not in _SPECS:
        raise ValueError(f"anomaly {text!r}: unknown kind {parts[0]!r}; expected one of band, bias, outage")
    cls, required, optional = _SPECS[kind]
    form = ":".join([kind, *required]) + "".join(f"[:{o}" for o in optional) + "]" * len(optional)
    args = parts[1:]
    if not len(required) <= len(args) <= len(required) + len(optional):
        raise ValueError(f"anomaly {text!r}: expected {form}, got {len(args)} field(s)")
    values: list[Any] = []
    for name, raw in zip((*required, *optional), args, strict=False):
        if name == "AXIS":
            if raw.lower() not in _AXES:
                raise ValueError(f"anomaly {text!r}: AXIS must be v or h, got {raw!r} (expected {form})")
            values.append(_AXES[raw.lower()])
            continue
        try:
            values.append(float(raw))
        except ValueError:
            raise ValueError(
                f"anomaly {text!r}: {name} must be a number, got {raw!r} (expected {form})"
            ) from None
    try:
        return cls(*values)
    except ValueError as exc:
        raise ValueError(f"anomaly {text!r}: {exc}") from None


# --------------------------------------------------------------------------- config


@dataclass(frozen=True, slots=True)
class SimulationConfig:
    """Parameters of a simulated campaign (see the module Notes for the model).

    Attributes
    ----------
    days : campaign length in days.
    interval_s : epoch interval (s), a whole number of microseconds.
    start : first epoch, GPS time (naive datetime); default 2024-01-07 00:00:00, a GPS week start.
    station : station name; with ``stations > 1`` the prefix of ``SIM01``, ``SIM02``...
    stations : number of independent stations (seeds spawned from ``seed``).
    seed : non-negative integer seed of the ``numpy.random.SeedSequence``.
    sigma_v0 : vertical PL-model 1-sigma scale (m). The median VPL is ``k_v * sigma_v0`` times
        the median set-event factor: about 13.5-14 m with the defaults (2.3 m, like EGNOS).
    k_v, k_h : PL multipliers, VPL = k_v sigma_v, HPL = k_h sigma_h (DO-229E: 5.33, 6.0).
    h_to_v : ratio sigma_h / sigma_v before the horizontal geometry factor.
    sigma_ratio : f, error sigma = f * PL / K; f < 1 overbounded, f > 1 violated.
    correlation_s : Gauss-Markov correlation time of the errors (s); 0 gives white errors.
    tail_fraction : stationary share of the heavy-tail regime, in [0, 1].
    tail_scale : error sigma multiplier in the heavy-tail regime.
    tail_dwell_s : mean duration of a heavy-tail episode (s).
    tail_axis : axes the regime acts on, ``vertical``, ``horizontal`` or ``both``.
    geometry_log_sd : standard deviation of the vertical log-geometry factor g_v.
    h_geometry_log_sd : standard deviation of the horizontal log-geometry factor g_h.
    iono_amplitude : A, log-amplitude of the diurnal ionospheric factor (peak 14:00 local).
    longitude_deg : longitude (deg east) giving local solar time for the ionospheric factor.
    set_rate_per_hour : rate of satellite set events.
    set_jump_mean : mean log-jump of a set event (exponentially distributed).
    set_relax_s : relaxation time constant of a set event (s).
    set_log_max : X, saturation of the summed set-event log-factor, X tanh(x / X) (caps PL excursions).
    outage_rate_per_day, outage_mean_s : Poisson rate and mean exponential duration of
        no-solution episodes (rows kept, NaN).
    gap_rate_per_day, gap_mean_s : the same for gaps (rows missing from the table).
    anomalies : band, bias and outage anomalies (objects or spec strings).
    """

    days: float = 7.0
    interval_s: float = 1.0
    start: dt.datetime = dt.datetime(2024, 1, 7)
    station: str = "SIM"
    stations: int = 1
    seed: int = 0
    sigma_v0: float = 2.3
    k_v: float = 5.33
    k_h: float = 6.0
    h_to_v: float = 0.55
    sigma_ratio: float = 0.4
    correlation_s: float = 120.0
    tail_fraction: float = 1e-3
    tail_scale: float = 3.0
    tail_dwell_s: float = 300.0
    tail_axis: str = "both"
    geometry_log_sd: float = 0.25
    h_geometry_log_sd: float = 0.1
    iono_amplitude: float = 0.3
    longitude_deg: float = 0.0
    set_rate_per_hour: float = 2.0
    set_jump_mean: float = 0.6
    set_relax_s: float = 600.0
    set_log_max: float = 3.0
    outage_rate_per_day: float = 2.0
    outage_mean_s: float = 30.0
    gap_rate_per_day: float = 1.0
    gap_mean_s: float = 60.0
    anomalies: tuple[Anomaly, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        _validate_config(self)

    @property
    def n_epochs(self) -> int:
        """Epochs on the grid of one station (before gaps)."""
        return round(self.days * 86400.0 / self.interval_s)

    @property
    def interval_us(self) -> int:
        return round(self.interval_s * 1e6)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (``start`` ISO 8601, anomalies as specs); inverse of :meth:`from_dict`."""
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["start"] = self.start.isoformat()
        d["anomalies"] = [a.spec for a in self.anomalies]
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> SimulationConfig:
        d = dict(d)
        if isinstance(d.get("start"), str):
            d["start"] = dt.datetime.fromisoformat(d["start"])
        d["anomalies"] = tuple(d.get("anomalies", ()))
        return cls(**d)


def _validate_config(c: SimulationConfig) -> None:
    anomalies = tuple(parse_anomaly(a) if isinstance(a, str) else a for a in c.anomalies)
    for a in anomalies:
        if not isinstance(a, BandAnomaly | BiasAnomaly | OutageAnomaly):
            raise ValueError(
                f"anomalies: expected BandAnomaly, BiasAnomaly, OutageAnomaly or a spec, got {a!r}"
            )
    object.__setattr__(c, "anomalies", anomalies)
    if str(c.tail_axis).lower() not in _TAIL_AXES:
        raise ValueError(f"tail_axis {c.tail_axis!r}: expected 'vertical', 'horizontal' or 'both'")
    object.__setattr__(c, "tail_axis", _TAIL_AXES[str(c.tail_axis).lower()])
    if not isinstance(c.start, dt.datetime) or c.start.tzinfo is not None:
        raise ValueError(f"start must be a naive datetime in GPS time, got {c.start!r}")
    if not isinstance(c.station, str) or not c.station:
        raise ValueError(f"station must be a non-empty string, got {c.station!r}")
    for name in ("stations", "seed"):
        v = getattr(c, name)
        if isinstance(v, bool) or not isinstance(v, int | np.integer):
            raise ValueError(f"{name} must be an integer, got {v!r}")
    if c.stations < 1 or c.seed < 0:
        raise ValueError(f"need stations >= 1 and seed >= 0, got stations={c.stations}, seed={c.seed}")
    positive = (
        "days",
        "interval_s",
        "sigma_v0",
        "k_v",
        "k_h",
        "h_to_v",
        "sigma_ratio",
        "tail_scale",
        "tail_dwell_s",
        "set_relax_s",
        "set_log_max",
        "outage_mean_s",
        "gap_mean_s",
    )
    non_negative = (
        "correlation_s",
        "geometry_log_sd",
        "h_geometry_log_sd",
        "iono_amplitude",
        "set_rate_per_hour",
        "set_jump_mean",
        "outage_rate_per_day",
        "gap_rate_per_day",
    )
    for name in (*positive, *non_negative, "longitude_deg", "tail_fraction"):
        v = getattr(c, name)
        if (
            isinstance(v, bool)
            or not isinstance(v, int | float | np.floating | np.integer)
            or not math.isfinite(v)
        ):
            raise ValueError(f"{name} must be a finite number, got {v!r}")
    for name in positive:
        if not getattr(c, name) > 0:
            raise ValueError(f"{name} must be > 0, got {getattr(c, name)}")
    for name in non_negative:
        if getattr(c, name) < 0:
            raise ValueError(f"{name} must be >= 0, got {getattr(c, name)}")
    if not 0 <= c.tail_fraction <= 1:
        raise ValueError(f"tail_fraction must be in [0, 1], got {c.tail_fraction}")
    if abs(c.interval_s * 1e6 - round(c.interval_s * 1e6)) > 1e-6 or round(c.interval_s * 1e6) < 1:
        raise ValueError(f"interval_s must be a whole number of microseconds, got {c.interval_s}")
    if c.n_epochs < 1:
        raise ValueError(f"days={c.days} at interval_s={c.interval_s} gives no epoch")


# --------------------------------------------------------------------------- truth formulas


def p_exceed(
    axis: str,
    limit: np.ndarray | float,
    sigma: np.ndarray | float,
    *,
    bias: np.ndarray | float = 0.0,
    tail_fraction: float = 0.0,
    tail_scale: float = 1.0,
) -> np.ndarray:
    r"""Exact probability that the error of ``axis`` exceeds ``limit``.

    Parameters
    ----------
    axis
        ``vertical``: P(|X| > L), X ~ N(b, s^2). ``horizontal``: P(sqrt(E^2 + N^2) > L),
        E ~ N(0, s^2), N ~ N(b, s^2) independent (Rice).
    limit, sigma, bias
        L (m), s (m, > 0) and b (m), broadcast together.
    tail_fraction, tail_scale
        eps and c of the mixture (1 - eps) law(s) + eps law(c s).

    Returns
    -------
    numpy.ndarray
        The probability, accurate in relative terms down to ~1e-300.

    Notes
    -----
    .. math::

        P_v = \bar\Phi\big(\tfrac{L-b}{s}\big) + \bar\Phi\big(\tfrac{L+b}{s}\big),\qquad
        P_h = Q_{\chi'^2_2}(L^2/s^2;\ b^2/s^2),\ = e^{-L^2/(2 s^2)} \text{ when } b = 0,

    with :math:`\bar\Phi(x)` = ``scipy.special.ndtr(-x)`` and :math:`Q_{\chi'^2_2}` =
    ``scipy.stats.ncx2.sf`` (df = 2).

    Examples
    --------
    >>> float(p_exceed("v", 5.33, 1.0))  # 2 * Phi-bar(5.33)
    9.8...e-08
    >>> float(p_exceed("h", 6.0, 1.0))  # exp(-18)
    1.52...e-08
    """
    ax = _axis(axis)
    limit, sigma, bias = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (limit, sigma, bias)))
    fn = _p_exceed_v if ax == "vertical" else _p_exceed_h
    p = fn(limit, sigma, bias)
    if tail_fraction > 0:
        p = (1.0 - tail_fraction) * p + tail_fraction * fn(limit, tail_scale * sigma, bias)
    return p


def _p_exceed_v(limit: np.ndarray, s: np.ndarray, b: np.ndarray | None) -> np.ndarray:
    if b is None or not np.any(b):
        return 2.0 * special.ndtr(-limit / s)
    return special.ndtr((b - limit) / s) + special.ndtr((-b - limit) / s)


def _p_exceed_h(limit: np.ndarray, s: np.ndarray, b: np.ndarray | None) -> np.ndarray:
    u = np.asarray(limit / s)
    p = np.array(np.exp(-0.5 * u * u), dtype=float)
    if b is not None and np.any(b):
        nz = np.broadcast_to(b, p.shape) != 0
        nc = (np.broadcast_to(b, p.shape)[nz] / np.broadcast_to(s, p.shape)[nz]) ** 2
        p[nz] = stats.ncx2.sf(u[nz] ** 2, 2, nc)
    return p


# --------------------------------------------------------------------------- result


@dataclass(frozen=True, slots=True)
class StationTruth:
    """Realised per-station truth that is not a column.

    Attributes
    ----------
    name : station name.
    spawn_key : ``SeedSequence`` spawn key of the station (``()`` for a single station).
    gaps, outages : realised ``(start_s, end_s)`` intervals (s after ``start``); outages
        include forced ``outage`` anomalies.
    geometry_v, geometry_h : ``(period_s, amplitude, phase_rad)`` of each harmonic of g_v, g_h.
    n_set_events : satellite set events in the campaign.
    regime_switches : times (s) at which the regime changed; ``initial_regime`` the state at t = 0.
    """

    name: str
    spawn_key: tuple[int, ...]
    gaps: tuple[tuple[float, float], ...]
    outages: tuple[tuple[float, float], ...]
    geometry_v: tuple[tuple[float, float, float], ...]
    geometry_h: tuple[tuple[float, float, float], ...]
    n_set_events: int
    initial_regime: int
    regime_switches: tuple[float, ...]

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k in ("gaps", "outages", "geometry_v", "geometry_h", "spawn_key", "regime_switches"):
            d[k] = [list(x) if isinstance(x, tuple) else x for x in d[k]]
        return d


@dataclass(frozen=True, slots=True)
class Simulation:
    """A simulated campaign: the epoch table with truth columns, and its configuration.

    Attributes
    ----------
    table : epoch table (``time, station, hpe, vpe, hpl, vpl, east, north, nsv, mode``)
        plus the truth columns of :data:`TRUTH_COLUMNS`.
    config : the :class:`SimulationConfig` that produced it.
    stations : per-station realised truth (:class:`StationTruth`).
    """

    table: pl.DataFrame
    config: SimulationConfig
    stations: tuple[StationTruth, ...]

    def _solution(self, station: str | None) -> pl.DataFrame:
        t = self.table.filter(pl.col("vpl").is_not_nan())
        return t if station is None else t.filter(pl.col("station").cast(pl.String) == station)

    def _tail(self, axis: str) -> tuple[float, float]:
        c = self.config
        on = c.tail_axis in ("both", axis)
        return (c.tail_fraction, c.tail_scale) if on else (0.0, 1.0)

    def p_mi_true(self, axis: str, *, station: str | None = None) -> float:
        """Exact campaign P(|PE| > PL): mean of ``p_mi_<axis>_true`` over epochs with a solution.

        This is the expected empirical MI frequency of the campaign (NaN without solution epochs).
        """
        col = f"p_mi_{_axis(axis)[0]}_true"
        s = self._solution(station)[col]
        return float(s.mean()) if s.len() else math.nan

    def p_mi_true_band(self, axis: str, lo: float, hi: float, *, station: str | None = None) -> float:
        """:meth:`p_mi_true` over the epochs whose PL of ``axis`` lies in [lo, hi) m."""
        ax = _axis(axis)
        plc = "vpl" if ax == "vertical" else "hpl"
        s = self._solution(station).filter((pl.col(plc) >= lo) & (pl.col(plc) < hi))[f"p_mi_{ax[0]}_true"]
        return float(s.mean()) if s.len() else math.nan

    def p_hmi_true(
        self, axis: str, alert_limit: float, *, conditional: bool = True, station: str | None = None
    ) -> float:
        r"""Exact probability of hazardously misleading information for alert limit AL.

        Parameters
        ----------
        axis, alert_limit
            ``vertical``/``horizontal`` and AL (m).
        conditional
            True: mean over solution epochs with PL < AL of P(|PE| > AL) (the integrity
            risk given availability, as when PL >= AL epochs are filtered out, Veerman).
            False: the same sum divided by all solution epochs, i.e. P(PL < AL and
            |PE| > AL) (Kannemans 2006, section 2.1.3, P_HMI).

        Returns
        -------
        float
            The probability; NaN when no epoch qualifies.

        Notes
        -----
        Per epoch, :func:`p_exceed` with ``limit`` = AL, ``sigma`` = ``sigma_<axis>_true``,
        ``bias`` = ``bias_<axis>_true`` (0 without a bias anomaly) and the regime mixture:
        vertical :math:`\bar\Phi((AL-b)/s) + \bar\Phi((AL+b)/s)`, horizontal
        :math:`Q_{\chi'^2_2}(AL^2/s^2; b^2/s^2)`, mixed as :math:`(1-\varepsilon)P(s) + \varepsilon P(cs)`.
        """
        ax = _axis(axis)
        sol = self._solution(station)
        plc, sc, bc = (
            ("vpl", "sigma_v_true", "bias_v_true")
            if ax == "vertical"
            else ("hpl", "sigma_h_true", "bias_h_true")
        )
        sub = sol.filter(pl.col(plc) < alert_limit)
        denom = sub.height if conditional else sol.height
        if denom == 0:
            return math.nan
        if sub.height == 0:
            return 0.0
        bias = sub[bc].to_numpy() if bc in sub.columns else 0.0
        eps, c = self._tail(ax)
        p = p_exceed(ax, alert_limit, sub[sc].to_numpy(), bias=bias, tail_fraction=eps, tail_scale=c)
        return float(p.sum() / denom)

    def truth_dict(self) -> dict[str, Any]:
        """Config, per-station realised truth and campaign truth, JSON-ready (the Parquet metadata)."""
        sol = self._solution(None)
        from overbound import __version__

        eps_v, c_v = self._tail("vertical")
        eps_h, c_h = self._tail("horizontal")
        hmi: dict[str, dict[str, float | None]] = {}
        for name, svc in SERVICES.items():
            hmi[name] = {
                "horizontal": _json_float(self.p_hmi_true("horizontal", svc.hal)),
                "vertical": None if svc.val is None else _json_float(self.p_hmi_true("vertical", svc.val)),
            }
        return {
            "generator": f"overbound.simulate {__version__}",
            "config": self.config.to_dict(),
            "stations": [s.to_dict() for s in self.stations],
            "columns": dict(TRUTH_COLUMNS),
            "mixture": {
                "vertical": {"tail_fraction": eps_v, "tail_scale": c_v},
                "horizontal": {"tail_fraction": eps_h, "tail_scale": c_h},
            },
            "n_rows": self.table.height,
            "n_solution": sol.height,
            "p_mi_v_true": _json_float(self.p_mi_true("vertical")),
            "p_mi_h_true": _json_float(self.p_mi_true("horizontal")),
            "p_hmi_true_given_available": hmi,
        }


def _json_float(x: float) -> float | None:
    return None if not math.isfinite(x) else x


# --------------------------------------------------------------------------- simulation


def simulate(config: SimulationConfig | None = None) -> Simulation:
    """Simulate a receiver campaign with known truth.

    Parameters
    ----------
    config
        The campaign; ``SimulationConfig()`` (7 days, 1 Hz, seed 0) when None.

    Returns
    -------
    Simulation
        ``table`` (epoch table + truth columns, stations one after the other, time
        increasing), ``config`` and ``stations`` (realised truth).

    Notes
    -----
    Algorithm, per station (see the module Notes for the equations):

    1. Spawn the random streams from the station's ``SeedSequence``.
    2. Draw the geometry harmonics, the set events, the regime switching times, the
       gaps and the outages (Poisson processes drawn in fixed batches).
    3. Mark gap epochs (absent) and outage epochs (NaN) on the grid.
    4. In chunks of epochs: PLs, regime, AR(1) errors (``lfilter`` with its state
       carried over), biases, truth probabilities; keep the non-gap epochs.

    Examples
    --------
    >>> sim = simulate(SimulationConfig(days=0.01, seed=1))
    >>> sim.table.height <= 864, sim.table["mode"].drop_nulls().unique().to_list()
    (True, ['PA'])
    """
    config = SimulationConfig() if config is None else config
    parts = [_simulate_station(config, name, ss) for name, ss in _station_seeds(config)]
    table = parts[0][0] if len(parts) == 1 else pl.concat([p[0] for p in parts], how="vertical")
    return Simulation(table=table, config=config, stations=tuple(p[1] for p in parts))


def _station_seeds(config: SimulationConfig) -> list[tuple[str, np.random.SeedSequence]]:
    """Each station's name and ``SeedSequence``: the seed itself for one station, else its spawns."""
    if config.stations == 1:
        return [(config.station, np.random.SeedSequence(config.seed))]
    children = np.random.SeedSequence(config.seed).spawn(config.stations)
    return [(f"{config.station}{i + 1:02d}", ss) for i, ss in enumerate(children)]


def write_simulation_dataset(config: SimulationConfig, dataset: str | Path) -> list:
    """Simulate a network straight into a campaign dataset, one station-day at a time.

    Memory is one chunk of the grid plus one station-day, whatever the number of stations
    and days (a station-year at 1 Hz never sits in memory). Each partition is the station-day
    of :func:`simulate` with the same config, the same rows and values, written by
    :func:`~overbound.io.dataset.write_partition` with the provenance
    ``extra.simulation = {generator, config, station}`` (that station's realised truth); the
    manifest holds the config and every station's truth under ``simulation``.

    Returns
    -------
    list of :class:`~overbound.io.dataset.Partition` : the partitions written, in order.
    """
    from overbound import __version__
    from overbound.io.dataset import create_dataset, read_manifest, write_manifest, write_partition
    from overbound.output import locked

    root = create_dataset(dataset)
    generator = f"overbound.simulate {__version__}"
    written, truths = [], []
    with locked(root):
        for name, ss in _station_seeds(config):
            truth, chunks = _station_chunks(config, name, ss)
            extra = {
                "simulation": {"generator": generator, "config": config.to_dict(), "station": truth.to_dict()}
            }
            for day in _days(chunks):
                written.append(write_partition(root, day, extra=extra))
            truths.append(truth.to_dict())
        manifest = read_manifest(root)
        manifest["simulation"] = {"generator": generator, "config": config.to_dict(), "stations": truths}
        manifest.setdefault("stations", {}).update({t["name"]: {"reference": None} for t in truths})
        write_manifest(root, manifest)
    return written


def _days(chunks: Iterator[pl.DataFrame]) -> Iterator[pl.DataFrame]:
    """The chunks of a station regrouped by GPS day (one day held at a time)."""
    pending: list[pl.DataFrame] = []
    current = None
    for chunk in chunks:
        day = chunk["time"].dt.date()
        for d in day.unique(maintain_order=True).to_list():
            part = chunk.filter(day == d)
            if current is not None and d != current and pending:
                yield pl.concat(pending, how="vertical", rechunk=True)
                pending = []
            pending.append(part)
            current = d
    if pending:
        yield pl.concat(pending, how="vertical", rechunk=True)


def _marked_poisson(
    rng: np.random.Generator, rate_per_s: float, t_end: float, n_marks: int, mark_mean: float
) -> tuple[np.ndarray, np.ndarray]:
    """Event times in [0, t_end) of a Poisson process and exponential marks of mean ``mark_mean``.

    Drawn in fixed batches (gaps then marks) so that a longer ``t_end`` extends the sequence.
    """
    if rate_per_s <= 0:
        return np.empty(0), np.empty((0, n_marks))
    times, marks, t0 = [], [], 0.0
    while t0 < t_end:
        gaps = rng.exponential(1.0 / rate_per_s, _BATCH)
        m = rng.exponential(mark_mean, (_BATCH, n_marks))
        t = t0 + np.cumsum(gaps)
        times.append(t)
        marks.append(m)
        t0 = float(t[-1])
    t = np.concatenate(times)
    keep = t < t_end
    return t[keep], np.concatenate(marks)[keep]


def _regime_switches(rng: np.random.Generator, c: SimulationConfig, t_end: float) -> tuple[int, np.ndarray]:
    """Initial state and switching times of the stationary two-state chain."""
    eps = c.tail_fraction
    state0 = int(rng.random() < eps)
    if eps == 0.0 or eps == 1.0:
        return state0, np.empty(0)
    mean = np.array([c.tail_dwell_s * (1.0 - eps) / eps, c.tail_dwell_s])
    out, t0, k = [], 0.0, 0
    while t0 < t_end:
        means = mean[(state0 + k + np.arange(_BATCH)) % 2]
        t = t0 + np.cumsum(rng.exponential(1.0, _BATCH) * means)
        out.append(t)
        t0, k = float(t[-1]), k + _BATCH
    t = np.concatenate(out)
    return state0, t[t < t_end]


def _geometry(rng: np.random.Generator, log_sd: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(angular frequency, amplitude, phase) of the six sidereal harmonics, var = log_sd**2."""
    w = rng.uniform(0.3, 1.0, _HARMONICS.size) / np.sqrt(_HARMONICS)
    phase = rng.uniform(0.0, 2.0 * np.pi, _HARMONICS.size)
    amp = log_sd * np.sqrt(2.0) * w / np.sqrt(np.sum(w * w))
    return 2.0 * np.pi * _HARMONICS / SIDEREAL_DAY_S, amp, phase


def _simulate_station(
    c: SimulationConfig, name: str, ss: np.random.SeedSequence
) -> tuple[pl.DataFrame, StationTruth]:
    """The table of one station (its chunks, concatenated) and its realised truth."""
    truth, chunks = _station_chunks(c, name, ss)
    parts = list(chunks)
    return (parts[0] if len(parts) == 1 else pl.concat(parts, how="vertical", rechunk=True)), truth


def _interval_mask(intervals: np.ndarray, k0: int, k1: int, dt_s: float) -> np.ndarray:
    """Mask of the grid epochs ``k0 <= k < k1`` with ``s <= k dt < e`` for some interval ``(s, e)``."""
    d = np.zeros(k1 - k0 + 1, dtype=np.int32)
    if len(intervals):
        lo = np.clip(np.ceil(intervals[:, 0] / dt_s - 1e-9), k0, k1).astype(np.int64) - k0
        hi = np.clip(np.ceil(intervals[:, 1] / dt_s - 1e-9), k0, k1).astype(np.int64) - k0
        np.add.at(d, lo, 1)
        np.add.at(d, hi, -1)
    return np.cumsum(d[:-1]) > 0


def _station_chunks(
    c: SimulationConfig, name: str, ss: np.random.SeedSequence
) -> tuple[StationTruth, Iterator[pl.DataFrame]]:
    """The realised truth of one station, and its epoch table as consecutive chunks of the grid.

    Memory is one chunk (:data:`_CHUNK` grid epochs) plus the station's events, whatever the
    campaign's length: a station-year streams into a dataset one day at a time. The chunks
    concatenated are the station's table.
    """
    n, dt_s = c.n_epochs, c.interval_s
    t_end = n * dt_s
    streams = [np.random.default_rng(s) for s in ss.spawn(8)]
    r_geo, r_set, r_reg, r_gap, r_out, r_zv, r_ze, r_zn = streams

    # 2. slow processes and events
    om_v, amp_v, ph_v = _geometry(r_geo, c.geometry_log_sd)
    om_h, amp_h, ph_h = _geometry(r_geo, c.h_geometry_log_sd)
    set_t, set_j = _marked_poisson(r_set, c.set_rate_per_hour / 3600.0, t_end, 1, c.set_jump_mean)
    set_j = set_j[:, 0]
    state0, switches = _regime_switches(r_reg, c, t_end)
    g_t, g_d = _marked_poisson(r_gap, c.gap_rate_per_day / 86400.0, t_end, 1, c.gap_mean_s)
    o_t, o_d = _marked_poisson(r_out, c.outage_rate_per_day / 86400.0, t_end, 1, c.outage_mean_s)
    gaps = np.column_stack([g_t, g_t + g_d[:, 0]]) if g_t.size else np.empty((0, 2))
    forced = [
        (a.start_h * 3600.0, a.start_h * 3600.0 + a.duration_s)
        for a in c.anomalies
        if isinstance(a, OutageAnomaly)
    ]
    outs = np.vstack(
        [
            np.column_stack([o_t, o_t + o_d[:, 0]]) if o_t.size else np.empty((0, 2)),
            np.array(forced, dtype=float).reshape(-1, 2),
        ]
    )
    outs = outs[np.argsort(outs[:, 0], kind="stable")]

    def _triples(om: np.ndarray, amp: np.ndarray, ph: np.ndarray) -> tuple[tuple[float, float, float], ...]:
        return tuple((float(2 * np.pi / o), float(a), float(p)) for o, a, p in zip(om, amp, ph, strict=True))

    truth = StationTruth(
        name=name,
        spawn_key=tuple(int(k) for k in ss.spawn_key),
        gaps=tuple((float(a), float(b)) for a, b in gaps),
        outages=tuple((float(a), float(b)) for a, b in outs),
        geometry_v=_triples(om_v, amp_v, ph_v),
        geometry_h=_triples(om_h, amp_h, ph_h),
        n_set_events=int(set_t.size),
        initial_regime=state0,
        regime_switches=tuple(float(x) for x in switches),
    )

    def chunks() -> Iterator[pl.DataFrame]:
        biases = [a for a in c.anomalies if isinstance(a, BiasAnomaly)]
        bands = [a for a in c.anomalies if isinstance(a, BandAnomaly)]
        has_bias = bool(biases)
        # 4. chunks with carried filter states
        phi = math.exp(-dt_s / c.correlation_s) if c.correlation_s > 0 else 0.0
        b_ar, a_ar = np.array([math.sqrt(1.0 - phi * phi)]), np.array([1.0, -phi])
        zi = {
            "v": phi * r_zv.standard_normal(1),
            "e": phi * r_ze.standard_normal(1),
            "n": phi * r_zn.standard_normal(1),
        }
        alpha = math.exp(-dt_s / c.set_relax_s)
        k_set = np.ceil(set_t / dt_s - 1e-9).astype(np.int64)
        w_set = set_j * np.exp(-(k_set * dt_s - set_t) / c.set_relax_s)
        zi_set = np.zeros(1)
        sod0 = (c.start - c.start.replace(hour=0, minute=0, second=0, microsecond=0)).total_seconds()
        iono_om, iono_t0 = 2.0 * np.pi / 86400.0, 14.0 * 3600.0 - sod0 - c.longitude_deg * 240.0
        f = c.sigma_ratio
        eps_v, c_v = (c.tail_fraction, c.tail_scale) if c.tail_axis in ("both", "vertical") else (0.0, 1.0)
        eps_h, c_h = (c.tail_fraction, c.tail_scale) if c.tail_axis in ("both", "horizontal") else (0.0, 1.0)
        log_sv0, log_r = math.log(c.sigma_v0), math.log(c.h_to_v)
        start_us = round((c.start - dt.datetime(1970, 1, 1)).total_seconds() * 1e6)

        for k0 in range(0, n, _CHUNK):
            k1 = min(n, k0 + _CHUNK)
            length = k1 - k0
            t = np.arange(k0, k1, dtype=float) * dt_s
            g_v = np.zeros(length)
            g_h = np.zeros(length)
            for j in range(_HARMONICS.size):
                g_v += amp_v[j] * np.sin(om_v[j] * t + ph_v[j])
                g_h += amp_h[j] * np.sin(om_h[j] * t + ph_h[j])
            sel = (k_set >= k0) & (k_set < k1)
            impulses = np.bincount(k_set[sel] - k0, weights=w_set[sel], minlength=length)
            x_set, zi_set = signal.lfilter([1.0], [1.0, -alpha], impulses, zi=zi_set)
            g_v += c.set_log_max * np.tanh(x_set / c.set_log_max)
            nsv_c = np.clip(np.rint(_NSV_MID - _NSV_SLOPE * g_v), _NSV_MIN, _NSV_MAX).astype(np.int16)
            log_sv = g_v
            log_sv += log_sv0
            log_sv += c.iono_amplitude * np.cos(iono_om * (t - iono_t0))
            sigma_v = np.exp(log_sv)
            g_h += log_sv
            g_h += log_r
            sigma_h = np.exp(g_h)
            vpl = c.k_v * sigma_v
            hpl = c.k_h * sigma_h
            s_v = (f / c.k_v) * vpl
            s_h = (f / c.k_h) * hpl
            for a in bands:
                if a.axis == "vertical":
                    s_v[(vpl >= a.lo) & (vpl < a.hi)] *= a.factor
                else:
                    s_h[(hpl >= a.lo) & (hpl < a.hi)] *= a.factor
            reg = ((state0 + np.searchsorted(switches, t, side="right")) & 1).astype(np.int8)
            z_v, zi["v"] = signal.lfilter(b_ar, a_ar, r_zv.standard_normal(length), zi=zi["v"])
            z_e, zi["e"] = signal.lfilter(b_ar, a_ar, r_ze.standard_normal(length), zi=zi["e"])
            z_n, zi["n"] = signal.lfilter(b_ar, a_ar, r_zn.standard_normal(length), zi=zi["n"])
            mult_v = np.where(reg == 1, c_v, 1.0) if eps_v > 0 else 1.0
            mult_h = np.where(reg == 1, c_h, 1.0) if eps_h > 0 else 1.0
            vpe = s_v * mult_v * z_v
            east = s_h * mult_h * z_e
            north = s_h * mult_h * z_n
            b_v = b_h = None
            if has_bias:
                b_v, b_h = np.zeros(length), np.zeros(length)
                for a in biases:
                    (b_v if a.axis == "vertical" else b_h)[:] += a.value(t)
                vpe += b_v
                north += b_h
            p_v = _p_exceed_v(vpl, s_v, b_v)
            p_h = _p_exceed_h(hpl, s_h, b_h)
            if eps_v > 0:
                p_v = (1.0 - eps_v) * p_v + eps_v * _p_exceed_v(vpl, c_v * s_v, b_v)
            if eps_h > 0:
                p_h = (1.0 - eps_h) * p_h + eps_h * _p_exceed_h(hpl, c_h * s_h, b_h)

            # 3. gaps (absent epochs) and outages (no solution) of this stretch of the grid
            idx = np.flatnonzero(~_interval_mask(gaps, k0, k1, dt_s))
            outage = _interval_mask(outs, k0, k1, dt_s)[idx]
            cols = {
                "hpe": np.hypot(east[idx], north[idx]),
                "vpe": vpe[idx],
                "hpl": hpl[idx],
                "vpl": vpl[idx],
                "east": east[idx],
                "north": north[idx],
                "sigma_v_true": s_v[idx],
                "sigma_h_true": s_h[idx],
                "p_mi_v_true": p_v[idx],
                "p_mi_h_true": p_h[idx],
            }
            if has_bias:
                cols["bias_v_true"], cols["bias_h_true"] = b_v[idx], b_h[idx]
            for arr in cols.values():
                arr[outage] = np.nan
            yield _chunk_table(
                name, (idx + k0) * c.interval_us + start_us, cols, nsv_c[idx], ~outage, reg[idx]
            )

    return truth, chunks()


_TRUTH_ORDER = ("sigma_v_true", "sigma_h_true", "bias_v_true", "bias_h_true", "p_mi_v_true", "p_mi_h_true")


def _chunk_table(
    name: str, time_us: np.ndarray, cols: dict, nsv: np.ndarray, solution: np.ndarray, regime: np.ndarray
) -> pl.DataFrame:
    """One chunk of a station's table: the epoch-table columns, then the truth columns."""
    df = pl.DataFrame(
        [
            pl.Series("time", time_us, dtype=pl.Int64).cast(pl.Datetime("us")),
            *(pl.Series(k, cols[k]) for k in ("hpe", "vpe", "hpl", "vpl", "east", "north")),
            pl.Series("nsv", nsv),
            pl.Series("_sol", solution),
        ]
    )
    df = df.select(
        "time",
        pl.lit(name, dtype=pl.String).cast(pl.Categorical).alias("station"),
        "hpe",
        "vpe",
        "hpl",
        "vpl",
        "east",
        "north",
        pl.when(pl.col("_sol")).then(pl.col("nsv")).otherwise(None).cast(pl.Int16).alias("nsv"),
        pl.when(pl.col("_sol")).then(pl.lit("PA")).otherwise(None).cast(pl.Categorical).alias("mode"),
    )
    truth = [pl.Series(k, cols[k]) for k in _TRUTH_ORDER if k in cols]
    return df.hstack([*truth, pl.Series("regime", regime)])


# --------------------------------------------------------------------------- files


def write_simulation(sim: Simulation, path: str | Path) -> Path:
    """Write the table: Parquet (``.parquet``/``.pq``) or CSV (``.csv``).

    Written by :func:`overbound.io.table.write_epochs`; Parquet carries
    :meth:`Simulation.truth_dict` in its provenance as ``extra.simulation``
    (:func:`overbound.io.table.read_epochs_metadata`); CSV gets it in a sidecar file
    ``<path>.json``. The same simulation gives byte-identical files.

    Raises
    ------
    ValueError
        Unknown suffix.
    """
    path = Path(path)
    truth = sim.truth_dict()
    write_epochs(sim.table, path, extra_metadata={"simulation": truth})
    if path.suffix.lower() == ".csv":  # CSV has no metadata block: the truth goes beside it
        Path(str(path) + ".json").write_text(json.dumps(truth, sort_keys=True, allow_nan=False) + "\n")
    return path


def read_simulation(path: str | Path) -> Simulation:
    """Read back a Parquet file written by :func:`write_simulation` (table, config and station truth).

    Raises
    ------
    ValueError
        The file has no ``overbound`` metadata.
    """
    path = Path(path)
    d = read_epochs_metadata(path).get("extra", {}).get("simulation")
    if d is None:
        raise ValueError(
            f"{path}: no simulation truth in the Parquet metadata: not written by write_simulation"
        )
    stations = tuple(
        StationTruth(
            name=s["name"],
            spawn_key=tuple(s["spawn_key"]),
            gaps=tuple(tuple(x) for x in s["gaps"]),
            outages=tuple(tuple(x) for x in s["outages"]),
            geometry_v=tuple(tuple(x) for x in s["geometry_v"]),
            geometry_h=tuple(tuple(x) for x in s["geometry_h"]),
            n_set_events=s["n_set_events"],
            initial_regime=s["initial_regime"],
            regime_switches=tuple(s["regime_switches"]),
        )
        for s in d["stations"]
    )
    return Simulation(pl.read_parquet(path), SimulationConfig.from_dict(d["config"]), stations)
