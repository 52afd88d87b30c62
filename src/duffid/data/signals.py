"""Excitation signals: steps, chirps (sweeps), multisines and their sums.

Every signal is a small immutable object that is called with time ``t`` [s]
and returns the excitation value(s): a numpy array of the same shape for
array input and a ``float`` for scalar input.  Each has a :attr:`~Signal.spec`
string that :func:`from_spec` parses back to an equal object, e.g.::

    step:10                      Step(10.0)
    step:10,0.05                 Step(10.0, t_on=0.05)
    chirp:2,0,20,10              Chirp(2.0, f0=0.0, f1=20.0, t1=10.0)
    sweep:2.96,2.5,20            Chirp.paper_sweep(2.96, 2.5, duration=20.0)
    multisine:1,1,30,2           Multisine(1.0, 1.0, 30.0, 2.0)
    multisine:1,1,30,2,random,7  Multisine(1.0, 1.0, 30.0, 2.0, "random", 7)
    zero                         Zero()
    step:10+multisine:0.5,1,30,2 Sum(Step(10.0), Multisine(0.5, 1.0, 30.0, 2.0))
"""

from __future__ import annotations

import math
import re
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError, OptionError

__all__ = ["Chirp", "Gated", "Multisine", "Signal", "Step", "Sum", "Zero", "from_spec"]

_NUMBER_RE = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)
_SEED_RE = re.compile(r"\d+", re.ASCII)
# '+' separating sum terms, i.e. not the sign of an exponent such as '1e+5'
_TERM_SPLIT_RE = re.compile(r"(?<![\d.][eE])\+")
_CHIRP_METHODS = ("linear", "quadratic", "logarithmic", "hyperbolic")
_PHASE_KINDS = ("schroeder", "random")
_MAX_COMPONENTS = 100_000
_EVAL_BLOCK = 1 << 20  # elements of the (time x component) block in Multisine
ACCEPTED_SPECS = (
    "step:A[,t_on]; chirp:A,f0,f1,t1[,linear|quadratic|logarithmic|hyperbolic]; "
    "sweep:A,rate,duration; multisine:A,f_min,f_max,period[,schroeder|random[,seed]]; "
    "zero; a term followed by @T is switched off from T seconds on (e.g. sweep:3,2.5,4@4, "
    "for a ring-down); terms joined with '+' are summed"
)


def _real(value: Any, name: str) -> float:
    """Return `value` as a finite float, or raise naming the parameter."""
    if isinstance(value, bool) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        raise OptionError(f"{name} must be a real number, got {value!r}")
    out = float(value)
    if not math.isfinite(out):
        raise InputError(f"{name} must be finite, got {out!r}")
    return out


def _num(value: float) -> str:
    """Shortest text that parses back to exactly `value` (no '+' in exponents)."""
    text = repr(float(value))
    if text.endswith(".0"):
        text = text[:-2]
    return text.replace("e+", "e")


class Signal(ABC):
    """Base class of excitation signals.

    Subclasses implement :meth:`_evaluate` on float arrays and :attr:`spec`.
    Signals can be added with ``+``, giving a :class:`Sum`.
    """

    def __call__(self, t: Any) -> Any:
        """Evaluate the signal.

        Parameters
        ----------
        t : float or array_like
            Time(s) [s].

        Returns
        -------
        float or numpy.ndarray
            A float for scalar `t`, otherwise a float64 array of the shape of `t`.
        """
        arr = np.asarray(t, dtype=np.float64)
        out = self._evaluate(arr)
        if arr.ndim == 0:
            return float(out)
        return np.asarray(out, dtype=np.float64).reshape(arr.shape)

    @abstractmethod
    def _evaluate(self, t: np.ndarray) -> np.ndarray:
        """Evaluate on a float64 array, returning an array of the same shape."""

    @property
    @abstractmethod
    def spec(self) -> str:
        """Text form that :func:`from_spec` parses back to an equal signal."""

    def __add__(self, other: object) -> Sum:
        if not isinstance(other, Signal):
            return NotImplemented
        return Sum(self, other)


@dataclass(frozen=True)
class Zero(Signal):
    """The zero signal, ``u(t) = 0``.  Spec: ``zero``."""

    def _evaluate(self, t: np.ndarray) -> np.ndarray:
        return np.zeros_like(t)

    @property
    def spec(self) -> str:
        """``'zero'``."""
        return "zero"


@dataclass(frozen=True)
class Step(Signal):
    r"""Step of height `amplitude` switched on at `t_on`.

    .. math:: u(t) = \begin{cases} A & t \ge t_\mathrm{on} \\ 0 & t < t_\mathrm{on} \end{cases}

    Parameters
    ----------
    amplitude : float
        Step height ``A`` (any sign).
    t_on : float, optional
        Switch-on time [s].

    Notes
    -----
    Spec: ``step:A`` or ``step:A,t_on``.
    """

    amplitude: float
    t_on: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "amplitude", _real(self.amplitude, "amplitude"))
        object.__setattr__(self, "t_on", _real(self.t_on, "t_on"))

    def _evaluate(self, t: np.ndarray) -> np.ndarray:
        return np.where(t >= self.t_on, self.amplitude, 0.0)

    @property
    def spec(self) -> str:
        """``'step:A'`` or ``'step:A,t_on'``."""
        if self.t_on == 0.0:
            return f"step:{_num(self.amplitude)}"
        return f"step:{_num(self.amplitude)},{_num(self.t_on)}"


@dataclass(frozen=True)
class Chirp(Signal):
    r"""Swept sine (chirp) starting at zero.

    .. math:: u(t) = A \sin\varphi(t), \qquad \varphi(0) = 0,

    with instantaneous frequency :math:`f(t) = \varphi'(t) / 2\pi` going from
    `f0` at ``t = 0`` to `f1` at ``t = t1`` according to `method`, with the
    frequency laws and phases of :func:`scipy.signal.chirp` (this equals
    ``A * scipy.signal.chirp(t, f0, t1, f1, method, phi=-90)``):

    ============  =====================================================
    linear        :math:`f = f_0 + (f_1 - f_0)\, t / t_1`,
                  :math:`\varphi = 2\pi (f_0 t + \tfrac{f_1 - f_0}{2 t_1} t^2)`
    quadratic     :math:`f = f_0 + (f_1 - f_0)\, t^2 / t_1^2`
    logarithmic   :math:`f = f_0 (f_1 / f_0)^{t / t_1}`
    hyperbolic    :math:`f = f_0 f_1 t_1 / ((f_0 - f_1) t + f_1 t_1)`
    ============  =====================================================

    The phase is evaluated in closed form and the sine taken directly, so
    ``u(0) = 0`` exactly.  The frequency law is not clamped: after `t1` it
    continues in the same way.

    Parameters
    ----------
    amplitude : float
        Amplitude ``A`` (any sign).
    f0, f1 : float
        Instantaneous frequencies [Hz] at ``t = 0`` and ``t = t1``, ``>= 0``
        (``> 0`` for the logarithmic and hyperbolic methods).
    t1 : float
        Time [s] at which the frequency reaches `f1`, ``> 0``.
    method : {'linear', 'quadratic', 'logarithmic', 'hyperbolic'}, optional
        Frequency law, as in :func:`scipy.signal.chirp`.

    Notes
    -----
    Spec: ``chirp:A,f0,f1,t1`` (linear) or ``chirp:A,f0,f1,t1,method``.
    """

    amplitude: float
    f0: float
    f1: float
    t1: float
    method: str = "linear"

    def __post_init__(self) -> None:
        for name in ("amplitude", "f0", "f1", "t1"):
            object.__setattr__(self, name, _real(getattr(self, name), name))
        if self.method not in _CHIRP_METHODS:
            raise InputError(
                f"method must be one of {', '.join(_CHIRP_METHODS)}, got {self.method!r}"
            )
        if self.t1 <= 0.0:
            raise InputError(f"t1 must be > 0, got {self.t1!r}")
        for name in ("f0", "f1"):
            value = getattr(self, name)
            if value < 0.0:
                raise InputError(f"{name} must be >= 0, got {value!r}")
            if value == 0.0 and self.method in ("logarithmic", "hyperbolic"):
                raise InputError(f"{name} must be > 0 for the {self.method} method")

    @classmethod
    def paper_sweep(
        cls, amplitude: float, rate: float = 2.5, *, duration: float
    ) -> Chirp:
        r"""Linear sweep of the reference paper, starting at 0 Hz.

        .. math:: u(t) = A \sin\left(2\pi \frac{r}{2} t^2\right),

        i.e. instantaneous frequency ``r t`` Hz; this is
        ``Chirp(A, 0, r * duration, duration, 'linear')``.

        Parameters
        ----------
        amplitude : float
            Amplitude ``A``.
        rate : float, optional
            Sweep rate ``r`` [Hz/s], ``> 0``.
        duration : float
            Time [s] at which the frequency reaches ``rate * duration``, ``> 0``.

        Returns
        -------
        Chirp
            The sweep.  Spec text ``sweep:A,rate,duration`` builds the same.
        """
        rate_v = _real(rate, "rate")
        duration_v = _real(duration, "duration")
        if rate_v <= 0.0:
            raise InputError(f"rate must be > 0, got {rate_v!r}")
        if duration_v <= 0.0:
            raise InputError(f"duration must be > 0, got {duration_v!r}")
        return cls(amplitude, 0.0, rate_v * duration_v, duration_v, "linear")

    def phase(self, t: Any) -> np.ndarray:
        r"""Phase :math:`\varphi(t)` [rad], with :math:`\varphi(0) = 0`.

        Parameters
        ----------
        t : array_like
            Time(s) [s].

        Returns
        -------
        numpy.ndarray
            The phase, same shape as `t`.
        """
        t = np.asarray(t, dtype=np.float64)
        f0, f1, t1 = self.f0, self.f1, self.t1
        if self.method == "linear":
            cycles = f0 * t + 0.5 * (f1 - f0) / t1 * t * t
        elif self.method == "quadratic":
            cycles = f0 * t + (f1 - f0) / (3.0 * t1 * t1) * t**3
        elif f0 == f1:
            cycles = f0 * t
        elif self.method == "logarithmic":
            beta = t1 / math.log(f1 / f0)
            cycles = beta * f0 * np.expm1(t / beta)
        else:  # hyperbolic
            sing = -f1 * t1 / (f0 - f1)
            cycles = -sing * f0 * np.log(np.abs(1.0 - t / sing))
        return 2.0 * np.pi * cycles

    def _evaluate(self, t: np.ndarray) -> np.ndarray:
        return self.amplitude * np.sin(self.phase(t))

    @property
    def spec(self) -> str:
        """``'chirp:A,f0,f1,t1'``, with ``',method'`` unless linear."""
        text = "chirp:" + ",".join(
            _num(v) for v in (self.amplitude, self.f0, self.f1, self.t1)
        )
        return text if self.method == "linear" else f"{text},{self.method}"


@dataclass(frozen=True)
class Multisine(Signal):
    r"""Periodic multisine with a prescribed peak value.

    .. math:: u(t) = c \sum_{j=1}^{K} \cos\left(2\pi f_j t + \phi_j\right),
              \qquad f_j = k_j / T,

    over all harmonics ``k_j >= 1`` of ``1/T`` (``T`` = `period`) with
    ``f_min <= f_j <= f_max`` (the DC term ``k = 0`` is never included).
    Phases are Schroeder's, :math:`\phi_j = -\pi j (j - 1) / K`, or drawn
    uniformly from :math:`[0, 2\pi)` with ``numpy.random.default_rng(seed)``.
    The scale ``c > 0`` makes :math:`\max_t |u(t)|` equal `amplitude`; the
    peak is searched on a grid of at least 32 points per period of the
    highest harmonic (FFT) and refined by Newton steps on the derivative.  ``u`` is
    periodic with period ``T``.

    Parameters
    ----------
    amplitude : float
        Peak value ``>= 0``.
    f_min, f_max : float
        Frequency band [Hz], ``0 <= f_min < f_max``; it must contain at least
        one harmonic of ``1/period``.
    period : float
        Period ``T`` [s], ``> 0``.
    phases : {'schroeder', 'random'}, optional
        Phase choice.
    seed : int, optional
        Seed of the random phases (``>= 0``; unused for Schroeder phases).

    Attributes
    ----------
    frequencies : numpy.ndarray
        The ``K`` component frequencies ``f_j`` [Hz].
    component_phases : numpy.ndarray
        The ``K`` phases ``phi_j`` [rad].
    scale : float
        The factor ``c``.

    Notes
    -----
    Spec: ``multisine:A,f_min,f_max,period[,schroeder|random[,seed]]``.
    """

    amplitude: float
    f_min: float
    f_max: float
    period: float
    phases: str = "schroeder"
    seed: int = 0
    _k: np.ndarray = field(init=False, repr=False, compare=False)
    _phi: np.ndarray = field(init=False, repr=False, compare=False)
    _scale: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name in ("amplitude", "f_min", "f_max", "period"):
            object.__setattr__(self, name, _real(getattr(self, name), name))
        if self.amplitude < 0.0:
            raise InputError(f"amplitude (the peak value) must be >= 0, got {self.amplitude!r}")
        if self.f_min < 0.0:
            raise InputError(f"f_min must be >= 0, got {self.f_min!r}")
        if not self.f_max > self.f_min:
            raise InputError(
                f"f_max must be > f_min, got f_min={self.f_min!r}, f_max={self.f_max!r}"
            )
        if self.period <= 0.0:
            raise InputError(f"period must be > 0, got {self.period!r}")
        if self.phases not in _PHASE_KINDS:
            raise InputError(
                f"phases must be one of {', '.join(_PHASE_KINDS)}, got {self.phases!r}"
            )
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)):
            raise OptionError(f"seed must be an integer, got {self.seed!r}")
        if self.seed < 0:
            raise InputError(f"seed must be >= 0, got {self.seed!r}")
        object.__setattr__(self, "seed", int(self.seed))
        k_lo = max(1, math.ceil(self.f_min * self.period - 1e-9))
        k_hi = math.floor(self.f_max * self.period + 1e-9)
        count = k_hi - k_lo + 1
        if count < 1:
            raise InputError(
                f"no harmonic of 1/period = {1.0 / self.period:g} Hz (other than DC) lies "
                f"in [f_min, f_max] = [{self.f_min:g}, {self.f_max:g}] Hz; use a longer "
                "period or a wider band"
            )
        if count > _MAX_COMPONENTS:
            raise InputError(
                f"[f_min, f_max] * period gives {count} components, more than "
                f"{_MAX_COMPONENTS}; use a shorter period or a narrower band"
            )
        k = np.arange(k_lo, k_hi + 1, dtype=np.float64)
        if self.phases == "schroeder":
            j = np.arange(1, count + 1, dtype=np.float64)
            phi = -np.pi * j * (j - 1.0) / count
        else:
            phi = np.random.default_rng(self.seed).uniform(0.0, 2.0 * np.pi, count)
        k.setflags(write=False)
        phi.setflags(write=False)
        object.__setattr__(self, "_k", k)
        object.__setattr__(self, "_phi", phi)
        peak = self._unit_peak(k_hi)
        object.__setattr__(self, "_scale", self.amplitude / peak)

    def _unit_sum(self, tau: np.ndarray) -> np.ndarray:
        """Unscaled sum of cosines at reduced times ``tau`` (1-D)."""
        omega = (2.0 * np.pi / self.period) * self._k
        out = np.empty(tau.shape[0], dtype=np.float64)
        block = max(1, _EVAL_BLOCK // omega.shape[0])
        for i in range(0, tau.shape[0], block):
            arg = np.multiply.outer(tau[i : i + block], omega) + self._phi
            out[i : i + block] = np.cos(arg).sum(axis=1)
        return out

    def _unit_peak(self, k_hi: int) -> float:
        """Peak of the unscaled sum over one period."""
        m = 1 << max(10, math.ceil(math.log2(32 * (k_hi + 1))))
        spectrum = np.zeros(m // 2 + 1, dtype=np.complex128)
        spectrum[self._k.astype(np.int64)] = np.exp(1j * self._phi)
        grid = (m / 2.0) * np.fft.irfft(spectrum, n=m)
        i = int(np.argmax(np.abs(grid)))
        h = self.period / m
        omega = (2.0 * np.pi / self.period) * self._k
        lo, hi = (i - 1) * h, (i + 1) * h
        tau = i * h
        for _ in range(30):  # Newton on u'(tau) = 0 near the grid maximum
            arg = omega * tau + self._phi
            d1 = -np.dot(omega, np.sin(arg))
            d2 = -np.dot(omega * omega, np.cos(arg))
            if d2 == 0.0:
                break
            new = min(max(tau - d1 / d2, lo), hi)
            if abs(new - tau) <= 1e-13 * self.period:
                tau = new
                break
            tau = new
        refined = abs(float(np.cos(omega * tau + self._phi).sum()))
        return max(float(np.abs(grid[i])), refined)

    @property
    def frequencies(self) -> np.ndarray:
        """Component frequencies ``k_j / period`` [Hz] (read-only)."""
        out = self._k / self.period
        out.setflags(write=False)
        return out

    @property
    def component_phases(self) -> np.ndarray:
        """Component phases ``phi_j`` [rad] (read-only)."""
        return self._phi

    @property
    def scale(self) -> float:
        """Scale factor ``c`` making the peak equal `amplitude`."""
        return self._scale

    def _evaluate(self, t: np.ndarray) -> np.ndarray:
        tau = np.mod(t.ravel(), self.period)
        return (self._scale * self._unit_sum(tau)).reshape(t.shape)

    @property
    def spec(self) -> str:
        """``'multisine:A,f_min,f_max,period'`` plus phases and seed unless default."""
        text = "multisine:" + ",".join(
            _num(v) for v in (self.amplitude, self.f_min, self.f_max, self.period)
        )
        if self.seed != 0:
            return f"{text},{self.phases},{self.seed}"
        if self.phases != "schroeder":
            return f"{text},{self.phases}"
        return text


@dataclass(frozen=True, init=False)
class Sum(Signal):
    r"""Sum of two or more signals, :math:`u(t) = \sum_i u_i(t)`.

    Parameters
    ----------
    *signals : Signal
        The terms; nested sums are flattened.  At least two terms.

    Notes
    -----
    Spec: the terms' specs joined with ``+``, e.g. ``step:10+multisine:0.5,1,30,2``.
    ``a + b`` for signals ``a``, ``b`` gives ``Sum(a, b)``.
    """

    terms: tuple[Signal, ...]

    def __init__(self, *signals: Signal) -> None:
        flat: list[Signal] = []
        for sig in signals:
            if isinstance(sig, Sum):
                flat.extend(sig.terms)
            elif isinstance(sig, Signal):
                flat.append(sig)
            else:
                raise OptionError(f"Sum terms must be signals, got {sig!r}")
        if len(flat) < 2:
            raise InputError(f"Sum needs at least 2 terms, got {len(flat)}")
        object.__setattr__(self, "terms", tuple(flat))

    def _evaluate(self, t: np.ndarray) -> np.ndarray:
        out = np.zeros_like(t)
        for term in self.terms:
            out = out + term._evaluate(t)
        return out

    @property
    def spec(self) -> str:
        """The terms' specs joined with ``+``."""
        return "+".join(term.spec for term in self.terms)


@dataclass(frozen=True)
class Gated(Signal):
    r"""A signal switched off from ``t_off`` on (e.g. a sweep followed by a ring-down).

    .. math:: u(t) = \begin{cases} s(t) & t < t_\mathrm{off} \\ 0 & t \ge t_\mathrm{off} \end{cases}

    Parameters
    ----------
    signal : Signal
        The signal to gate (not a :class:`Sum`: gate each term instead, so that the spec
        stays unambiguous).
    t_off : float
        Switch-off time [s].

    Notes
    -----
    Spec: the inner term's spec followed by ``@t_off``, e.g. ``sweep:3,2.5,4@4``.
    """

    signal: Signal
    t_off: float

    def __post_init__(self) -> None:
        if not isinstance(self.signal, Signal) or isinstance(self.signal, (Sum, Gated)):
            raise OptionError(f"Gated needs a single, ungated signal term, got {self.signal!r}")
        object.__setattr__(self, "t_off", _real(self.t_off, "t_off"))

    def _evaluate(self, t: np.ndarray) -> np.ndarray:
        return np.where(t < self.t_off, self.signal(t), 0.0)

    @property
    def spec(self) -> str:
        """``'<term>@t_off'``."""
        return f"{self.signal.spec}@{_num(self.t_off)}"


class _SpecError(ValueError):
    """Problem in one term of a spec (internal)."""


def _parse_term(term: str) -> Signal:
    """Parse one term (no '+') of a signal spec, optionally gated with ``@t_off``."""
    if "@" in term:
        inner, _, t_off = term.rpartition("@")
        if not _NUMBER_RE.fullmatch(t_off.strip()):
            raise _SpecError(f"switch-off time {t_off.strip()!r} after '@' is not a finite decimal number")
        if "@" in inner:
            raise _SpecError("a term takes at most one '@t_off'")
        return Gated(_parse_term(inner), float(t_off))
    kind, colon, rest = term.partition(":")
    kind = kind.strip().lower()
    args = [a.strip() for a in rest.split(",")] if colon else []
    arities: dict[str, tuple[int, int]] = {
        "zero": (0, 0),
        "step": (1, 2),
        "chirp": (4, 5),
        "sweep": (3, 3),
        "multisine": (4, 6),
    }
    if kind not in arities:
        raise _SpecError(f"unknown signal kind {kind!r}")
    lo, hi = arities[kind]
    if colon and kind == "zero":
        raise _SpecError("'zero' takes no parameters")
    if not lo <= len(args) <= hi:
        wanted = str(lo) if lo == hi else f"{lo} to {hi}"
        raise _SpecError(f"{kind} takes {wanted} parameters, got {len(args)}")
    names = {
        "step": ("amplitude", "t_on"),
        "chirp": ("amplitude", "f0", "f1", "t1"),
        "sweep": ("amplitude", "rate", "duration"),
        "multisine": ("amplitude", "f_min", "f_max", "period"),
    }.get(kind, ())
    values: list[float] = []
    for name, text in zip(names, args):
        if not _NUMBER_RE.fullmatch(text):
            raise _SpecError(f"{name} {text!r} is not a finite decimal number")
        values.append(float(text))
    try:
        if kind == "zero":
            return Zero()
        if kind == "step":
            return Step(*values)
        if kind == "sweep":
            return Chirp.paper_sweep(values[0], values[1], duration=values[2])
        if kind == "chirp":
            method = args[4].lower() if len(args) == 5 else "linear"
            if method not in _CHIRP_METHODS:
                raise _SpecError(
                    f"chirp method {args[4]!r} is not one of {', '.join(_CHIRP_METHODS)}"
                )
            return Chirp(*values, method=method)
        phases = args[4].lower() if len(args) >= 5 else "schroeder"
        if phases not in _PHASE_KINDS:
            raise _SpecError(
                f"multisine phases {args[4]!r} is not one of {', '.join(_PHASE_KINDS)}"
            )
        seed = 0
        if len(args) == 6:
            if not _SEED_RE.fullmatch(args[5]):
                raise _SpecError(f"seed {args[5]!r} is not a non-negative integer")
            seed = int(args[5])
        return Multisine(*values, phases=phases, seed=seed)
    except _SpecError:
        raise
    except (ValueError, TypeError) as exc:
        raise _SpecError(str(exc)) from None


def from_spec(text: str) -> Signal:
    """Build a signal from its spec text.

    Parameters
    ----------
    text : str
        One or more terms joined with ``+``; each term is one of
        ``step:A[,t_on]``, ``chirp:A,f0,f1,t1[,method]``,
        ``sweep:A,rate,duration`` (:meth:`Chirp.paper_sweep`),
        ``multisine:A,f_min,f_max,period[,schroeder|random[,seed]]`` or
        ``zero``.  Numbers are decimal (``2``, ``-0.5``, ``1e-3``); whitespace
        around parts is ignored; kind and option names are case-insensitive.
        Nothing is evaluated as code.

    Returns
    -------
    Signal
        The signal; a :class:`Sum` if there are several terms.

    Raises
    ------
    ValueError
        If the text is malformed or a parameter is invalid; the message quotes
        the spec text, names the wrong part and lists the accepted forms.
    """
    if not isinstance(text, str):
        raise OptionError(f"signal spec must be a string, got {text!r}")
    if not text.strip():
        raise InputError(f"invalid signal spec {text!r}: the spec is empty. "
                         f"Accepted forms: {ACCEPTED_SPECS}")
    terms = [part.strip() for part in _TERM_SPLIT_RE.split(text)]
    signals: list[Signal] = []
    for number, term in enumerate(terms, start=1):
        try:
            if not term:
                raise _SpecError(f"term {number} is empty")
            signals.append(_parse_term(term))
        except _SpecError as exc:
            where = f"in term {term!r}, " if term and len(terms) > 1 else ""
            raise InputError(
                f"invalid signal spec {text!r}: {where}{exc}. Accepted forms: {ACCEPTED_SPECS}"
            ) from None
    if len(signals) == 1:
        return signals[0]
    return Sum(*signals)
