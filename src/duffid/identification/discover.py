"""When the model does not fit: find the terms a record asks for (``duffid discover``).

Starting from a base equation (a named model's equations or the user's own), :func:`discover`
searches a library of physically meaningful terms (:data:`DEFAULT_LIBRARY`: x², x³, x⁵,
|x|·x, x²·ẋ, sign(ẋ) and a constant force; users add their own in the equation syntax of
:mod:`duffid.models.equation`) for the smallest set the record supports.

How a term is chosen
--------------------
1. **Screening, by cross-validation on held-out stretches** (cheap, numpy only). The base
   equation with every library term is written once as one equation model; the buffered
   method's rows (:class:`~duffid.identification.buffered.BufferedIdentifier`: Legendre
   coefficients of the integrated-by-parts equation, :data:`WINDOW_PERIODS` periods per
   window, windows side by side) are computed once. Terms are ranked by how much each lowers
   the equation error on stretches the fit did not see (:data:`FOLDS` contiguous folds):
   cross-validation rather than an information criterion, because the rows of neighbouring
   windows and the simulation errors of neighbouring samples are correlated, so that no
   count of samples is the right ``n`` for AIC or BIC, while a held-out stretch measures
   what a term predicts directly.
2. **Confirmation, by the checks of** :func:`~duffid.identification.trust.identify`: the best
   ranked term (then the next, up to :data:`CONFIRM_TRIES`) is added to the equation and the
   whole record identified with every check. The term is taken when the simulation of the
   identified model driven by the measured force removes at least :data:`MIN_GAIN` of what
   the current model leaves unexplained beyond the noise, and its coefficient is *present*:
   published (excited, determined within ``max_uncertainty`` by the bootstrap, physically
   signed), or, short of that, at least 1/:data:`PRESENCE_UNCERTAINTY` standard errors from
   zero with a physical sign. While the model does not yet reproduce the record,
   ``identify`` checks no coefficient (it says the model does not fit): a term that removes
   enough is then taken *provisionally*, and every provisional term must be present once
   the model reproduces the record; a term told absent then is dropped, and terms that never
   reach a model that reproduces the record are not taken (the notes say which).
3. The search stops when the model reproduces the record to its noise (simulation NRMSE at
   most :data:`NOISE_FIT` times the noise's share) and no term screens far better
   (:data:`STRONG_SCREENING`), when no term passes, or after ``max_terms`` terms. A model
   that explains the record to its noise gets a term only if the term removes
   :data:`MIN_GAIN` of the whole simulation error's variance: a term is never "found" in
   noise.

When no model explains the record, :func:`residual_shape` says what the remaining force
residual looks like (asymmetry, a hysteresis or friction loop, a dead zone, a change along
the record) from the smoothed record.

Velocity nonlinearities other than Coulomb friction (``abs(der(x))*der(x)``) cannot be
integrated by parts without differentiating the measured displacement, so the algebraic
estimator does not take them (:mod:`duffid.models.equation` rejects the term with that
reason); they are not in the library.
"""
from __future__ import annotations

import math
import re
import sys
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..data.record import Record
from ..errors import EquationError, InputError
from ..models.chain import Chain
from ..models.equation_model import EquationModel
from ..models.units import parameter_units
from .assessment import json_ready
from .buffered import BufferedIdentifier, velocity_signs
from .engine import Identification
from .options import check_options
from .sampling import content_frequency, noise_level
from .trust import identify

__all__ = ["DEFAULT_LIBRARY", "TERM_WORDS", "NOISE_FIT", "MIN_GAIN", "Candidate", "Discovery", "discover",
           "residual_shape"]

#: The default library: each term in the equation syntax, in the equation's own displacement
#: ``x`` (``x1``, ``x2`` ... in the equations of several masses), with its coefficient's name
#: and what it means in words.
DEFAULT_LIBRARY = ("x^2", "x^3", "x^5", "abs(x)*x", "x^2*der(x)", "sign(der(x))", "1")
#: Coefficient names of the default terms (other terms: ``d1``, ``d2`` ...).
TERM_NAMES = {"x^2": "k2", "x^3": "k3", "x^5": "k5", "abs(x)*x": "ka", "x^2*der(x)": "c2",
              "sign(der(x))": "fc", "1": "c0"}
#: What each default term adds, in words.
TERM_WORDS = {
    "x^2": "a quadratic stiffness (a spring stiffer one way than the other)",
    "x^3": "a cubic stiffness (hardening or softening)",
    "x^5": "a fifth-power stiffness (a spring that stiffens faster at large amplitude)",
    "abs(x)*x": "a stiffness growing with |x| (a piecewise-quadratic, symmetric spring)",
    "x^2*der(x)": "a damping growing with the amplitude (x²·ẋ)",
    "sign(der(x))": "dry (Coulomb) friction",
    "1": "a constant force (a force-sensor bias or a preload)",
}
#: A model reproduces the record to its noise when its simulation NRMSE is at most this
#: multiple of the noise's share.
NOISE_FIT = 1.2
#: Share of the unexplained variance (simulation NRMSE² minus the noise's) a term must
#: remove to enter (a quarter: with two terms missing, each alone may remove less than half).
MIN_GAIN = 0.25
#: A term whose coefficient is not published (not determined to ``max_uncertainty``) is still
#: present when its coefficient lies at least 1/PRESENCE_UNCERTAINTY standard errors from zero
#: (relative standard error at most this), physically signed, and its term excited.
PRESENCE_UNCERTAINTY = 0.2
#: Once the model reproduces the record to the noise estimate, a term is still tried when it
#: predicts the held-out stretches this much better (held-out error ratio at most this): a
#: noise estimate can be too high (a record with few samples per period).
STRONG_SCREENING = 0.5
#: Terms confirmed (identified with every check) per step, best screened first.
CONFIRM_TRIES = 2
#: Most terms added by default.
MAX_TERMS = 3
#: Contiguous folds of the screening's cross-validation.
FOLDS = 5
#: Screening window, in periods of the displacement's main frequency.
WINDOW_PERIODS = 4.0
#: Legendre coefficients per screening window (at most the window's samples).
SCREEN_TERMS = 24


@dataclass
class Candidate:
    """One equation tried: the base, or the base with added terms.

    Attributes
    ----------
    equation : str
        Its text.
    added : tuple of str
        The terms added to the base, in the equation syntax without their coefficients
        (``x^2``; in the equations of several masses the term in that mass's displacement,
        ``x2^2``).
    coefficients : tuple of str
        The added terms' coefficient names, in the order of ``added``.
    identification : Identification
        The checked identification of the record with it.
    model : EquationModel
        The equation as a model.
    units : dict
        Parameter -> unit (from the record's SI units, m and N).
    screening : float
        Held-out equation error relative to the model it was screened against (below 1: it
        predicts the held-out stretches better); NaN for the base.
    verdict : str
        ``base``, ``accepted`` or why the term was not taken, in words.
    """

    equation: str
    added: tuple[str, ...]
    coefficients: tuple[str, ...]
    identification: Identification
    model: EquationModel
    units: dict[str, str]
    screening: float = math.nan
    verdict: str = "base"

    @property
    def fit(self) -> dict[str, Any]:
        """The checked identification's fit figures (``simulation_nrmse``, ``noise_nrmse`` ...)."""
        return dict(self.identification.assessment.fit)

    @property
    def excess(self) -> float:
        """What the simulation misses beyond the noise (NRMSE, root of the difference of
        squares); infinite when the model escapes or cannot be simulated."""
        fit = self.identification.assessment.fit
        sim, noise = fit.get("simulation_nrmse", math.nan), fit.get("noise_nrmse", math.nan)
        if not (sim is not None and np.isfinite(sim)):
            return math.inf
        return math.sqrt(max(sim ** 2 - (noise if np.isfinite(noise) else 0.0) ** 2, 0.0))

    @property
    def explained(self) -> bool:
        """True when the simulation reproduces the record to its noise (:data:`NOISE_FIT`)."""
        fit = self.identification.assessment.fit
        sim, noise = fit.get("simulation_nrmse", math.nan), fit.get("noise_nrmse", math.nan)
        return bool(sim is not None and np.isfinite(sim) and sim <= NOISE_FIT * noise)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: equation, added terms, fit, parameters (published values or None),
        status, uncertainty (relative standard errors), units, screening and verdict."""
        result = self.identification
        a = result.assessment.to_dict()
        return {
            "equation": self.equation,
            "added": list(self.added),
            "fit": a["fit"],
            "parameters": json_ready(result.parameters),
            "status": a["status"],
            "uncertainty": a["uncertainty"],
            "units": dict(self.units),
            "screening": json_ready(self.screening),
            "verdict": self.verdict,
            "notes": a["notes"],
        }


@dataclass
class Discovery:
    """What :func:`discover` found.

    Attributes
    ----------
    base : str
        The base equation.
    best : Candidate
        The smallest supported equation that explains the record best (the base when no
        term was taken).
    candidates : list of Candidate
        Every equation identified with every check, in the order tried (the base first).
    screening : list of (tuple of str, list of (str, float))
        Each step of the search: the terms chosen before it, and every remaining term with
        its held-out equation error relative to without it, best first (below 1: the term
        predicts the held-out stretches better).
    notes : list of str
        What was found, in words.
    residual : dict or None
        When the best equation does not reproduce the record to its noise:
        :func:`residual_shape` of its force residual.
    seconds : float
        Wall-clock time of the search.
    """

    base: str
    best: Candidate
    candidates: list[Candidate]
    screening: list[tuple[tuple[str, ...], list[tuple[str, float]]]]
    notes: list[str] = field(default_factory=list)
    residual: dict[str, Any] | None = None
    seconds: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """The JSON object of ``duffid discover --json``."""
        return {
            "base": self.base,
            "best": self.best.to_dict(),
            "candidates": [c.to_dict() for c in self.candidates],
            "screening": [{"with": list(chosen), "terms": [{"term": term, "ratio": json_ready(r)} for term, r in ranking]}
                          for chosen, ranking in self.screening],
            "notes": list(self.notes),
            "residual": json_ready(self.residual),
            "seconds": self.seconds,
        }


# ---------------------------------------------------------------------- the library
@dataclass(frozen=True)
class _Term:
    """One library term placed in one equation."""

    text: str        #: the library's text, in x
    placed: str      #: in the equation's own displacement (``x2^2``)
    equation: int    #: index of the equation
    coefficient: str #: its coefficient's name
    label: str       #: as reported: ``placed``, with its equation when that is ambiguous


def _split_equations(text: str) -> list[str]:
    return [e.strip() for e in text.split(";") if e.strip()]


def _placed(term: str, displacement: str) -> str:
    """``term`` (in ``x``) written in ``displacement``."""
    return re.sub(r"\bx\b", displacement, term)


def _terms(base: EquationModel, library: Sequence[str], columns: Sequence[str]) -> list[_Term]:
    """The library's terms, one per equation of the base (in that equation's displacement),
    with coefficient names not already taken."""
    taken = set(base.parameters) | set(columns)
    n_eq = len(base.texts)
    displacements = ["x"] if "x" in columns else [f"x{i + 1}" for i in range(base.n_dof)]
    out = []
    generic = 0
    for text in library:
        text = text.strip()
        if not text:
            raise InputError("--library: an empty term")
        stem = TERM_NAMES.get(text.replace(" ", ""))
        if stem is None:
            generic += 1
            stem = f"d{generic}"
        for i in range(n_eq):
            name = stem if n_eq == 1 else f"{stem}_eq{i + 1}"
            while name in taken:
                name += "b"
            taken.add(name)
            where = displacements[min(i, len(displacements) - 1)]
            placed = _placed(text, where)
            label = placed if n_eq == 1 or placed != text else f"{placed} (equation {i + 1})"
            out.append(_Term(text, placed, i, name, label))
    return out


def _with_terms(base_texts: Sequence[str], terms: Sequence[_Term]) -> str:
    """The base equations with ``terms`` added to the left-hand sides."""
    texts = list(base_texts)
    for term in terms:
        left, right = texts[term.equation].split("=", 1)
        product = term.coefficient if term.placed == "1" else f"{term.coefficient}*{term.placed}"
        texts[term.equation] = f"{left.rstrip()} + {product} ={right}"
    return "; ".join(texts)


def _check_term(base_texts: Sequence[str], term: _Term, columns: Sequence[str]) -> None:
    """An :class:`InputError` naming ``term`` when the equation syntax or the estimator refuses it."""
    try:
        EquationModel(_with_terms(base_texts, [term]), columns)
    except (EquationError, InputError) as exc:
        raise InputError(f"--library: the term {term.text!r} cannot be identified: {exc}") from None


# ---------------------------------------------------------------------- screening
def _screening_rows(record: Record, model: EquationModel, frequency: float
                    ) -> list[tuple[list[int], list[str], list[np.ndarray], list[np.ndarray]]]:
    """Per least-squares block of the equations: its equations, unknowns, and the buffered
    method's rows ``A`` and ``D`` of every window side by side."""
    n = record.n_samples
    period = record.fs / frequency if np.isfinite(frequency) and frequency > 0 else n / 8
    samples = int(min(max(WINDOW_PERIODS * period, 3 * SCREEN_TERMS), n - 1))
    reg = model.regression()
    screen = BufferedIdentifier(reg, record.dt, "legendre", window=samples * record.dt,
                                n_terms=min(SCREEN_TERMS, samples))
    N = screen.n_intervals
    G = reg.evaluate(record.x, record.f, record.t, velocity_signs(record.x))
    blocks: list[tuple[list[int], list[str], list[np.ndarray], list[np.ndarray]]] = []
    for end in range(N, n, N):
        for b, (eqs, names, A, D) in enumerate(screen.block_systems(G[end - N:end + 1])):
            if b == len(blocks):
                blocks.append((eqs, names, [], []))
            blocks[b][2].append(A)
            blocks[b][3].append(D)
    return blocks


def _held_out_error(A: list[np.ndarray], D: list[np.ndarray], columns: list[int]) -> float:
    """Equation error on held-out folds of windows (sum of squares over the held-out
    right-hand sides'), fitting ``columns`` of the rows on the other folds."""
    n = len(A)
    folds = min(FOLDS, n)
    if folds < 2 or not columns:
        return math.nan
    edges = np.linspace(0, n, folds + 1).astype(int)
    error = total = 0.0
    for k in range(folds):
        train = [j for j in range(n) if not edges[k] <= j < edges[k + 1]]
        test = range(edges[k], edges[k + 1])
        At = np.vstack([A[j][:, columns] for j in train])
        Dt = np.concatenate([D[j] for j in train])
        scale = np.linalg.norm(At, axis=0)
        scale[scale == 0] = 1.0
        theta = np.linalg.lstsq(At / scale, Dt, rcond=None)[0] / scale
        for j in test:
            error += float(np.sum((D[j] - A[j][:, columns] @ theta) ** 2))
            total += float(np.sum(D[j] ** 2))
    return error / total if total > 0 else math.nan


class _Screen:
    """The screening's rows for the base with every library term, and the held-out error of
    any subset of the terms."""

    def __init__(self, record: Record, base: EquationModel, terms: list[_Term], columns: Sequence[str],
                 frequency: float) -> None:
        full = EquationModel(_with_terms(base.texts, terms), columns)
        self.blocks = _screening_rows(record, full, frequency)
        self.base_names = set(base.parameters)
        self.duplicates = self._duplicates(terms)

    def block(self, term: _Term) -> tuple[list[int], list[str], list[np.ndarray], list[np.ndarray]]:
        """The least-squares block holding ``term``'s equation."""
        return next(b for b in self.blocks if term.equation in b[0])

    def _duplicates(self, terms: list[_Term]) -> set[str]:
        """Coefficients of terms whose rows are a multiple of a base term's (already in the base)."""
        out = set()
        for term in terms:
            _, names, As, _ = self.block(term)
            A = np.vstack(As)
            column = A[:, names.index(term.coefficient)]
            norm = np.linalg.norm(column)
            if norm == 0:
                out.add(term.coefficient)
                continue
            for j, name in enumerate(names):
                if name in self.base_names:
                    other = A[:, j]
                    denominator = norm * np.linalg.norm(other)
                    if denominator > 0 and abs(float(column @ other)) / denominator > 1 - 1e-9:
                        out.add(term.coefficient)
        return out

    def error(self, term: _Term, chosen: Sequence[str]) -> float:
        """Held-out equation error of ``term``'s block with the base's and ``chosen`` coefficients."""
        _, names, A, D = self.block(term)
        columns = [j for j, k in enumerate(names) if k in self.base_names or k in chosen]
        return _held_out_error(A, D, columns)


# ---------------------------------------------------------------------- search
def _base_text(base: str | Chain | EquationModel) -> str:
    """The base's equations as text."""
    if isinstance(base, EquationModel):
        return "; ".join(base.texts)
    if isinstance(base, Chain):
        return base.equation_text()
    return str(base)


def discover(record: Record, base: str | Chain | EquationModel = "duffing1", *,
             library: Sequence[str] | None = None, max_terms: int = MAX_TERMS, refine: bool = False,
             progress: bool | None = None, jobs: int | None = None,
             log: Callable[[str], Any] | None = None, **options: Any) -> Discovery:
    """Find the smallest set of library terms that the record supports.

    Parameters
    ----------
    record : Record
        Forces and displacements (SI units: m, N).
    base : str, Chain or EquationModel
        The base equation: its text (``"m*der(x,2) + b*der(x) + k*x + kp*x^3 = f"``), a
        model name of the registry (``duffing1``, ``duffing2``: that model's equations), or
        a model.
    library : sequence of str, optional
        Candidate terms in the equation syntax, in ``x`` and ``der(x)`` (each placed in every
        equation in that equation's displacement); default :data:`DEFAULT_LIBRARY`. ``"1"`` is
        a constant force.
    max_terms : int
        Most terms added.
    refine : bool
        Refine the chosen equation's values by output-error least squares where the algebraic
        estimate leaves excited values undetermined, as
        :func:`~duffid.identification.trust.identify` does by default (seconds to a minute
        more). Off by default: the candidates are judged without it (it never changes
        whether a term is present, only how many values are published), and the notes name
        the values ``identify --equation`` would refine.
    progress : bool or None
        A line on stderr per identification (None: on a terminal).
    jobs : int or None
        Threads of each identification's checks (see :func:`~duffid.identification.trust.identify`).
    log : callable, optional
        Receives each progress line instead of stderr.
    **options
        Options of the robust method for every identification (``max_uncertainty`` ...).

    Returns
    -------
    Discovery

    Raises
    ------
    InputError
        A library term the estimator cannot take, or a base that is not an equation.
    """
    from ..models.registry import MODEL_NAMES, model_from_name

    started = time.perf_counter()
    record.require_displacement("duffid discover (a displacement record)")
    if max_terms < 0:
        raise InputError(f"--max-terms must be at least 0, got {max_terms}")
    check_options("robust", options)  # an unknown option named before any work
    columns = record.column_names
    if isinstance(base, str) and base.strip() in MODEL_NAMES:
        base = model_from_name(base.strip(), record.n_dof)
    if isinstance(base, Chain) and base.n_dof != record.n_dof:
        raise InputError(f"{record.source}: the base {base.name} has {base.n_dof} masses, the record "
                         f"{record.n_dof} displacement{'s' if record.n_dof > 1 else ''} "
                         f"({', '.join(c for c in columns if c.startswith('x'))})")
    base_text = _base_text(base)
    base_model = EquationModel(base_text, columns)
    texts = list(base_model.texts)
    terms = _terms(base_model, DEFAULT_LIBRARY if library is None else library, columns)
    checked: set[str] = set()
    for term in terms:
        if term.text not in checked:
            _check_term(texts, term, columns)
            checked.add(term.text)
    if progress is None:
        progress = sys.stderr.isatty()
    say = log if log is not None else ((lambda line: print(line, file=sys.stderr)) if progress else (lambda line: None))

    def identified(added: list[_Term], screening: float = math.nan, refined: bool = False) -> Candidate:
        text = _with_terms(texts, added)
        model = EquationModel(text, columns)
        say(f"duffid discover: identifying {text}" + (" (with the output-error refinement)" if refined else ""))
        result = identify(record, model, progress=False, jobs=jobs, refine=refined, **options)
        units = _units(model)
        return Candidate(text, tuple(t.label for t in added), tuple(t.coefficient for t in added), result,
                         model, units, screening)

    current = identified([])
    candidates = [current]
    notes: list[str] = []
    content = content_frequency(record.x, record.dt, noise=noise_level(record.x))
    screen = _Screen(record, base_model, terms, columns, content)
    for term in terms:
        if term.coefficient in screen.duplicates:
            notes.append(f"{term.label}: already in the base equation (not searched)")
    pool = [t for t in terms if t.coefficient not in screen.duplicates]
    screening: list[tuple[tuple[str, ...], list[tuple[str, float]]]] = []
    chosen: list[_Term] = []
    confirmed = current  # the last equation whose added terms are all present
    while pool and len(chosen) < max_terms:
        order = _ranked(screen, pool, [t.coefficient for t in chosen])
        screening.append((tuple(t.label for t in chosen), [(t.label, r) for t, r in order]))
        accepted = None
        tries = [(term, ratio) for term, ratio in order[:CONFIRM_TRIES] if ratio < 1.0]
        if current.explained:  # only a term that predicts far better: the noise may be overestimated
            tries = [(term, ratio) for term, ratio in tries[:1] if ratio <= STRONG_SCREENING]
        for term, ratio in tries:
            trial = identified(chosen + [term], ratio)
            trial.verdict = _verdict(trial, term, current)
            candidates.append(trial)
            if not trial.verdict.startswith("not taken"):
                accepted = (term, trial)
                break
        if accepted is None:
            break
        term, current = accepted
        chosen.append(term)
        pool.remove(term)
        absent = [t for t in chosen if _presence(current, t) not in ("present", "unknown")]
        if absent:  # a term taken before is now told absent (the model reproduces the record now)
            chosen = [t for t in chosen if t not in absent]
            current = identified(chosen)
            current.verdict = "accepted without " + ", ".join(t.label for t in absent)
            candidates.append(current)
        if all(_presence(current, t) == "present" for t in chosen):
            confirmed = current
    if screening and not any(np.isfinite(r) for _, r in screening[0][1]):
        notes.append(f"the record is too short to screen terms on held-out stretches ({FOLDS} stretches of "
                     f"{WINDOW_PERIODS:g} periods of its main frequency at most, 2 at least): none was tried")
    if current is not confirmed:
        provisional = [t.label for t in chosen if t.label not in confirmed.added]
        notes.append(f"{', '.join(provisional)}: improve the fit, but the model with "
                     f"{'them' if len(provisional) > 1 else 'it'} still does not reproduce the record, so "
                     f"{'their coefficients' if len(provisional) > 1 else 'its coefficient'} cannot be checked: "
                     f"not taken")
        current = confirmed
        chosen = [t for t in chosen if t.label in confirmed.added]
    best = current
    if refine and "uncertain" in best.identification.assessment.status.values():
        refined = identified(chosen, best.screening, refined=True)
        refined.verdict = best.verdict
        candidates[candidates.index(best)] = best = refined
    notes = _words(best, candidates[0], chosen, max_terms, pool) + notes
    undetermined = [k for k, v in best.identification.assessment.status.items() if v == "uncertain"]
    if undetermined and not refine and best.identification.assessment.fit.get("explained", False):
        notes.append(f"{', '.join(undetermined)}: not determined by the algebraic estimate alone; "
                     f"duffid identify --equation \"{best.equation}\" refines them by output error (or "
                     f"discover --refine)")
    residual = None
    if not best.explained:
        residual = residual_shape(record, best.model, best.identification.estimates)
        notes.append(residual["words"])
    return Discovery(base_text, best, candidates, screening, notes, residual,
                     time.perf_counter() - started)


def _ranked(screen: _Screen, pool: list[_Term], chosen: list[str]) -> list[tuple[_Term, float]]:
    """``pool``'s terms by held-out equation error with ``chosen`` (relative to without), best first."""
    out = []
    for term in pool:
        before = screen.error(term, chosen)
        after = screen.error(term, chosen + [term.coefficient])
        out.append((term, after / before if before > 0 else math.nan))
    out.sort(key=lambda item: item[1] if np.isfinite(item[1]) else math.inf)
    return out


def _presence(candidate: Candidate, term: _Term) -> str:
    """``present`` (published, or at least 1/:data:`PRESENCE_UNCERTAINTY` standard errors from
    zero with a physical sign: a term that carries little of the force balance, not excited
    enough for its value to be published, can still shape the motion), ``unknown`` (the identification refused the whole model
    because it does not reproduce the record) or why the term is absent, in words."""
    a = candidate.identification.assessment
    name = term.coefficient
    status = a.status.get(name, "unknown")
    value = a.values.get(name, candidate.identification.estimates.get(name, math.nan))
    uncertainty = a.uncertainty.get(name, math.nan)
    if status == "published":
        return "present"
    if status not in ("uncertain", "not excited"):  # a term of little force can still shape the motion
        return f"its coefficient {name} is {status}"
    if not np.isfinite(uncertainty):
        return "unknown" if not a.fit.get("explained", False) else f"its coefficient {name} is not determined"
    if uncertainty > PRESENCE_UNCERTAINTY:
        return f"its coefficient {name} is not told from zero (relative standard error {100 * uncertainty:.2g} %)"
    if not candidate.model.is_physical(name, value):
        return f"its coefficient {name} = {value:.4g} has the sign of no physical {term.text}"
    return "present"


def _verdict(trial: Candidate, term: _Term, current: Candidate) -> str:
    """``accepted``; ``provisional: ...`` when the term removes enough of the unexplained
    variance but the model with it does not reproduce the record yet (so that its
    coefficient cannot be checked); or why ``term`` was not taken."""
    presence = _presence(trial, term)
    if presence not in ("present", "unknown"):
        return f"not taken: {presence}"
    if not np.isfinite(trial.excess):
        return "not taken: the model with it does not reproduce the record (its simulation escapes)"
    # beyond the noise; or, when the current model already reaches the noise estimate, of the
    # whole simulation error (which a correct noise estimate leaves no room to halve)
    before, after = ((current.excess, trial.excess) if not current.explained else
                     (current.fit["simulation_nrmse"], trial.fit["simulation_nrmse"]))
    removed = 1 - after ** 2 / before ** 2 if np.isfinite(before) and before > 0 else 1.0
    if removed < MIN_GAIN:
        what = "unexplained variance" if not current.explained else "simulation error's variance"
        return f"not taken: it removes {100 * removed:.0f} % of the {what} ({100 * MIN_GAIN:.0f} % needed)"
    if presence == "unknown":
        return (f"provisional: it removes {100 * removed:.0f} % of the unexplained variance; its coefficient is "
                "checked once the model reproduces the record")
    return "accepted"


def _words(best: Candidate, base: Candidate, chosen: list[_Term], max_terms: int,
           pool: list[_Term]) -> list[str]:
    """The search's outcome in words."""
    fit = best.identification.assessment.fit
    sim, noise = fit.get("simulation_nrmse", math.nan), fit.get("noise_nrmse", math.nan)
    finite = sim is not None and np.isfinite(sim)
    shown = f"{100 * sim:.3g} % RMS (noise {100 * noise:.2g} %)" if finite else "an escaping simulation"
    if not chosen:
        if base.explained:
            return [f"the base equation reproduces the record to its noise ({shown}): nothing to add"]
        misses = f"misses the measured displacement by {shown}" if finite else \
            "does not reproduce the record (its simulation escapes)"
        return [f"no library term is supported by the record: the base equation {misses}, and no term makes "
                "it fit with a published coefficient"]
    added = "; ".join(f"{t.label}: {TERM_WORDS.get(t.text, 'the term ' + t.text)}" for t in chosen)
    lines = [f"the record asks for {len(chosen)} term{'s' if len(chosen) > 1 else ''} beyond the base "
             f"({added}); with {'them' if len(chosen) > 1 else 'it'} the model misses the measured "
             f"displacement by {shown}"]
    cubic = re.search(r"([A-Za-z_]\w*)\s*\*\s*x\s*\^\s*3\b", best.equation)
    quadratic = next((t for t in chosen if t.text == "x^2"), None)
    if quadratic is not None and cubic is not None:
        values = best.identification.parameters
        k2, kp = values.get(quadratic.coefficient, math.nan), values.get(cubic.group(1), math.nan)
        implied = (f" (here x0 = -{quadratic.coefficient}/(3 {cubic.group(1)}) = {-k2 / (3 * kp):.4g} m)"
                   if np.isfinite(k2) and np.isfinite(kp) and kp != 0 else "")
        lines.append("a quadratic stiffness next to a cubic one is also what a displacement-sensor offset "
                     f"looks like (k(x - x0) + kp(x - x0)^3 holds an x^2 term and a constant){implied}: if the "
                     "spring should be symmetric, try duffid identify --offset displacement")
    if not best.explained and len(chosen) >= max_terms and pool:
        lines.append(f"stopped after {max_terms} terms (--max-terms) before the record was explained")
    return lines


def _units(model: EquationModel) -> dict[str, str]:
    """Parameter units from the record's SI signals (m, N; s for time)."""
    sig = model.regressor.signals
    units = {name: "m" for name in sig.x_names} | {name: "N" for name in sig.f_names}
    try:
        return parameter_units(model, units)
    except InputError:
        return {}


# ---------------------------------------------------------------------- residual
#: The residual's smoothing keeps the displacement's spectrum where it stands this far above
#: the noise floor (power ratio).
SIGNAL_OVER_NOISE = 10.0


def smoothing_cutoff(record: Record) -> float:
    """The highest frequency [Hz] at which the displacement's power spectrum (Welch, of the
    first DOF) stands :data:`SIGNAL_OVER_NOISE` times above the white-noise floor of
    :func:`~duffid.identification.sampling.noise_level` (harmonics of a nonlinear response
    included), at most 0.4 of the sampling rate."""
    from scipy.signal import welch

    noise = float(noise_level(record.x)[0])
    segment = int(min(record.n_samples, max(256, 8 * record.fs)))
    frequencies, power = welch(record.x[:, 0], fs=record.fs, nperseg=segment)
    floor = 2.0 * noise ** 2 / record.fs  # one-sided density of white noise of that variance
    above = np.nonzero(power > SIGNAL_OVER_NOISE * floor)[0]
    highest = float(frequencies[above[-1]]) if len(above) else 0.1 * record.fs
    return min(max(highest, 2.0 * frequencies[1]), 0.4 * record.fs)

#: Shapes of what a model leaves unexplained: name -> (terms in ``x`` that describe it, in the
#: equation syntax; ``W`` stands for a fifth of the largest displacement), what it means.
SHAPES: dict[str, tuple[tuple[str, ...], str]] = {
    "asymmetry": (("x^2", "abs(x)", "x^4", "1"),
                  "even in the displacement (an asymmetric spring, a preload or a sensor offset)"),
    "hysteresis": (("sign(der(x))", "sign(der(x))*x", "sign(der(x))*x^2"),
                   "dependent on the direction of motion (a hysteresis or friction loop)"),
    "dead zone": (("x*exp(-(x/W)^2)", "sign(x)"),
                  "odd in the displacement and concentrated near rest (a dead zone or a clearance)"),
    "time variation": (("t*x", "t*x^3", "t"),
                       "changing along the record (a parameter that drifts: temperature, wear, a loosening joint)"),
    "stronger stiffness": (("x^5", "x^7", "abs(x)*x"),
                           "odd in the displacement and growing fast at large amplitude (a higher-order spring)"),
}
#: A shape is named when its terms remove at least this share of the held-out equation error.
SHAPE_SHARE = 0.3


def residual_shape(record: Record, model: EquationModel, values: Mapping[str, float]) -> dict[str, Any]:
    """What ``model`` (with the identified ``values``) leaves unexplained on ``record``.

    Each shape of :data:`SHAPES` is tried as extra terms of the first equation, on the
    screening's rows (integrated by parts: no derivative of the noisy displacement), and
    scored by the share of the held-out equation error it removes; the best one is named
    when it removes at least :data:`SHAPE_SHARE`. For a plot, the force residual is also
    evaluated pointwise with the displacement low-pass filtered without phase shift
    (8th-order Butterworth at :func:`smoothing_cutoff`, where its spectrum meets the noise)
    and differentiated: that residual holds the differentiated noise too.

    Returns
    -------
    dict
        ``shape`` (the best shape's name or ``"unstructured"``), ``explained`` (the share of
        the held-out equation error its terms remove), ``shares`` (every shape's), ``words``,
        and for a plot ``rms`` and ``force_rms`` (N) of the pointwise residual and the
        force, and its samples ``x``, ``v``, ``residual`` (at most 4,000, evenly picked).
    """
    from scipy.signal import butter, sosfiltfilt

    columns = record.column_names
    texts = list(model.texts)
    first = "x" if "x" in columns else "x1"
    width = f"{0.2 * float(np.max(np.abs(record.x[:, 0]))):.6g}"
    frequency = content_frequency(record.x, record.dt, noise=noise_level(record.x))
    shares = {}
    for name, (terms, _) in SHAPES.items():
        extra = [_Term(t, _placed(t.replace("W", width), first), 0, f"shape{j + 1}", t) for j, t in enumerate(terms)]
        block = next(b for b in _screening_rows(record, EquationModel(_with_terms(texts, extra), columns), frequency)
                     if 0 in b[0])
        _, names, A, D = block
        known = [j for j, k in enumerate(names) if k in model.parameters]
        without = _held_out_error(A, D, known)
        with_shape = _held_out_error(A, D, list(range(len(names))))
        shares[name] = float(1 - with_shape / without) if without > 0 else (math.nan if math.isnan(without) else 0.0)
    scored = {k: v for k, v in shares.items() if np.isfinite(v)}
    shape, explained = max(scored.items(), key=lambda item: item[1]) if scored else ("unknown", math.nan)
    if not scored:
        words = (f"the record is too short to tell what the model leaves unexplained (held-out stretches of "
                 f"{WINDOW_PERIODS:g} periods are needed on both sides)")
    elif explained < SHAPE_SHARE:
        words = (f"what the model leaves unexplained has none of the shapes duffid knows (the closest, {shape}, "
                 f"removes {100 * max(explained, 0.0):.0f} % of the held-out equation error)")
        shape = "unstructured"
    else:
        words = (f"what the model leaves unexplained looks like {shape}: {SHAPES[shape][1]}; terms of that shape "
                 f"remove {100 * explained:.0f} % of the held-out equation error")
    cutoff = smoothing_cutoff(record)
    edge = int(4 * record.fs / cutoff)
    out = {"shape": shape, "explained": explained, "shares": shares, "rms": math.nan, "force_rms": math.nan,
           "words": words, "x": [], "v": [], "residual": []}
    if record.n_samples < 4 * edge:  # too short for the filter's edges: no pointwise residual
        return out
    x = sosfiltfilt(butter(8, cutoff, fs=record.fs, output="sos"), record.x, axis=0)
    v = np.gradient(x, record.dt, axis=0)
    a = np.gradient(v, record.dt, axis=0)
    clean = {k: (float(val) if np.isfinite(val) else 0.0) for k, val in values.items()}
    residual = model.equation_residuals(clean, x, v, a, record.f, record.t)[edge:-edge, 0]
    x1, v1 = x[edge:-edge, 0], v[edge:-edge, 0]
    rms = math.sqrt(float(np.mean(residual ** 2)))
    force_rms = math.sqrt(float(np.mean(record.f[edge:-edge, 0] ** 2)))
    pick = np.linspace(0, len(residual) - 1, min(len(residual), 4000)).astype(int)
    out.update(rms=rms, force_rms=force_rms, x=x1[pick].tolist(), v=v1[pick].tolist(),
               residual=residual[pick].tolist())
    return out
