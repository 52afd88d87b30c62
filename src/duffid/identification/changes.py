"""Where a record's plant changed, and each stretch between the changes identified.

:func:`find_changes` runs the online estimator's change test (see
:data:`duffid.identification.engine.CHANGE_WINDOWS`) over a whole record: each time a
parameter turns ``changed``, the record's plant changed before that sample. The change
itself happened between the *onset* (the start of the first window whose prediction error,
:attr:`~duffid.identification.engine.Estimate.residual`, jumped to
:data:`~duffid.identification.engine.CHANGE_SURPRISE` times its level before; for a slow
drift, which makes no jump, the window and the test's memory before the flag) and the flag.

:func:`identify_segments` identifies the stretches between the changes with
:func:`duffid.identification.trust.identify` and all its checks: the samples from each flag
on (the test flags a change only once the windows after it have shown it) to the onset of
the next change.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..data.record import Record
from ..errors import BuildError, CompilerNotFoundError, InputError, RecordError
from ..models.chain import Chain
from .c_core import CIdentifier
from .engine import CHANGE_SURPRISE, CHANGE_WINDOWS, STATUSES, OnlineIdentifier
from .options import options_of

__all__ = ["Change", "Segment", "find_changes", "identify_segments", "change_test_options"]


@dataclass(frozen=True)
class Change:
    """A change of the plant found by the online change test.

    Attributes
    ----------
    flagged : float
        Time the test flagged it [s from the record's first sample].
    onset : float
        The earliest it can have happened [s]: the start of the window whose prediction
        error jumped before the flag, else the window and the test's memory before it.
    parameters : tuple of str
        The parameters (public names) whose value departed.
    """

    flagged: float
    onset: float
    parameters: tuple[str, ...]

    def describe(self) -> str:
        """In words: ``"k changed between 2.95 s and 3.31 s"``."""
        names = ", ".join(self.parameters) or "the plant"
        return f"{names} changed between {self.onset:.3g} s and {self.flagged:.3g} s"


@dataclass(frozen=True)
class Segment:
    """A stretch of the record between changes [s from its first sample], and its
    identification (None, with the reason in ``note``, when the stretch cannot be identified)."""

    start: float
    stop: float
    result: Any
    note: str = ""


def change_test_options(options: dict[str, Any]) -> dict[str, Any]:
    """Those of ``options`` (of :func:`~duffid.identification.trust.identify`) that the
    online change test reads: the robust online method's."""
    online = {o.name for o in options_of("robust")}
    return {k: v for k, v in options.items() if k in online and k != "nominal"}


def _online_rows(record: Record, model: Chain, options: dict[str, Any]
                 ) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Parameter names, and the statuses, residuals and window lengths of every sample (the C
    core where it builds)."""
    dt = record.dt
    try:
        ident = CIdentifier(model, dt, **options)
        rows = ident.run(record.x, record.f)
        names = list(ident.parameter_names)
        return names, rows["status"][:, :len(names)], rows["residual"].copy(), rows["window"].copy()
    except (CompilerNotFoundError, BuildError):
        ident = OnlineIdentifier(model, dt, **options)
        names = list(ident.parameter_names)
        estimates = [ident.update(x, f) for x, f in zip(record.x, record.f)]
        status = np.array([[STATUSES.index(e.status[n]) for n in names] for e in estimates])
        return (names, status, np.array([e.residual for e in estimates]),
                np.array([e.window for e in estimates]))


def find_changes(record: Record, model: Chain, **options: Any) -> list[Change]:
    """The changes of the plant the online change test finds over ``record``.

    Parameters
    ----------
    record : Record
        Forces and displacements, evenly sampled.
    model : Chain
        Model structure.
    **options
        Options of the robust online method (``change_threshold``, ``change_memory``, ...).

    Returns
    -------
    list of Change
        In time order; empty for a plant that did not change (as far as the test sees).

    Raises
    ------
    InputError
        Options that turn the test off (``change_threshold=None``) or are invalid.
    """
    record.require_displacement("the change test")
    if "change_threshold" in options and options["change_threshold"] is None:
        raise InputError("find_changes needs the change test: change_threshold must not be None")
    names, status, residual, window = _online_rows(record, model, dict(options))
    t = record.t - record.t[0]
    changed = status == STATUSES.index("changed")
    turned = changed & ~np.vstack([np.zeros((1, len(names)), bool), changed[:-1]])
    flags = np.flatnonzero(turned.any(axis=1))
    out: list[Change] = []
    last = 0
    for k in flags:
        memory = options.get("change_memory", "auto")
        window_s = float(window[k]) if np.isfinite(window[k]) else 0.0
        lookback = window_s + (CHANGE_WINDOWS * window_s if memory in ("auto", None) else float(memory))
        lo = max(last, int(np.searchsorted(t, t[k] - lookback)))
        before = residual[last:lo]
        level = float(np.nanmedian(before)) if np.isfinite(before).any() else np.nan
        jumps = np.flatnonzero(residual[lo:k + 1] > CHANGE_SURPRISE * level) if np.isfinite(level) else []
        # the window whose prediction error jumped holds the change somewhere in its span
        onset = max(t[lo + int(jumps[0])] - window_s, t[lo]) if len(jumps) else t[lo]
        out.append(Change(float(t[k]), float(onset), tuple(n for j, n in enumerate(names) if turned[k, j])))
        last = k
    return out


def identify_segments(record: Record, model: Chain, changes: list[Change] | None = None,
                      **options: Any) -> list[Segment]:
    """Identify each stretch of ``record`` between the plant's changes with every check.

    Parameters
    ----------
    record : Record
        Forces and displacements, evenly sampled.
    model : Chain
        Model structure.
    changes : list of Change, optional
        Where the plant changed (default: :func:`find_changes` with ``options``).
    **options
        Options of :func:`duffid.identification.trust.identify` (and of the change test).

    Returns
    -------
    list of Segment
        One per stretch: from the start (or a change's flag) to the next change's onset (or
        the end); a stretch that cannot be identified (too short) has no result and a note
        saying why.
    """
    from .trust import identify  # noqa: PLC0415 (identify runs the estimator this module checks)

    if changes is None:
        changes = find_changes(record, model, **change_test_options(options))
    t0, end = float(record.t[0]), float(record.t[-1] - record.t[0])
    bounds = [0.0, *(c for change in changes for c in (change.onset, change.flagged)), end]
    segments = []
    for start, stop in zip(bounds[::2], bounds[1::2]):
        try:
            result = identify(record.slice(t0 + start, t0 + stop), model, **options)
        except (InputError, RecordError) as exc:
            segments.append(Segment(start, stop, None, str(exc)))
            continue
        segments.append(Segment(start, stop, result))
    return segments
