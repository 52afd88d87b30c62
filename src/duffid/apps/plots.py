"""Plots written to files (matplotlib's object-oriented API: no pyplot state, no global backend change)."""
from __future__ import annotations

import math
import os
from typing import Mapping

import numpy as np  # noqa: E402
from matplotlib.figure import Figure

from ..analysis.silverbox import ARROW_NO_EXTRAPOLATION, FS, SKIP, TEST_RECORDS, SilverboxResult
from ..data.record import Record  # noqa: E402
from ..identification.engine import Identification  # noqa: E402

__all__ = ["plot_estimates", "plot_record", "plot_hilbert", "plot_eta_vs_amplitude", "plot_closed_loop", "plot_payload",
           "plot_silverbox", "plot_discovery_residual"]


def plot_estimates(result: Identification, path: str | os.PathLike[str], *,
                   truth: Mapping[str, float] | None = None,
                   series: Mapping[str, np.ndarray] | None = None, title: str | None = None,
                   run_label: str = "estimator run") -> None:
    """Estimates vs time, one panel per parameter (like the paper's Figures 8, 12, 13).

    Parameters
    ----------
    result : Identification
        Result of :func:`duffid.identify`: the estimator's run; with its assessment, each
        panel's title gives the status and standard error and the published value is drawn.
    path : path
        PNG file to write.
    truth : mapping, optional
        True values drawn as dashed lines.
    series : mapping, optional
        Extra curves to plot instead of ``result.history`` (e.g. ratios ``b2/m2``).
    title : str, optional
        Figure title.
    run_label : str
        Legend of the history's curves.
    """
    curves = dict(series) if series is not None else dict(result.history)
    assessment = getattr(result, "assessment", None)
    n = len(curves)
    cols = 2 if n > 3 else 1
    rows = int(np.ceil(n / cols))
    fig = Figure(figsize=(6 * cols, 2.2 * rows))
    axes = fig.subplots(rows, cols, sharex=True, squeeze=False)
    for ax, (name, values) in zip(axes.flat, curves.items()):
        ax.plot(result.t, values, lw=1.2, label=run_label)
        if truth is not None and name in truth:
            ax.axhline(truth[name], color="k", ls="--", lw=0.8, label="truth")
            finite = values[np.isfinite(values)]
            if finite.size:  # zoom on the truth: early transients would hide the result
                span = max(abs(truth[name]) * 0.2, 1e-12)
                ax.set_ylim(truth[name] - span, truth[name] + span)
        if assessment is not None and name in assessment.status:  # what the text and JSON say
            value = result.parameters.get(name, math.nan)
            if np.isfinite(value):
                ax.axhline(value, color="C1", lw=1.0, label="published")
            u = assessment.uncertainty.get(name, math.nan)
            ax.set_title(f"{name}: {assessment.status[name]}"
                         + (f", standard error {100 * u:.2g} %" if np.isfinite(u) else ""), fontsize=9)
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
    for ax in axes.flat[n:]:
        ax.set_visible(False)
    if result.t_identified is not None:
        for ax in axes.flat[:n]:
            ax.axvline(result.t_identified, color="g", lw=0.6, alpha=0.6)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    axes.flat[0].legend(loc="best", fontsize=8)
    fig.suptitle(title or f"{result.model}, method {result.method}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_record(record: Record, path: str | os.PathLike[str], *, title: str | None = None) -> None:
    """Forces and displacements of a record vs time."""
    fig = Figure(figsize=(7, 4.5))
    ax_f, ax_x = fig.subplots(2, 1, sharex=True)
    names = record.column_names[1:]
    for k in range(record.n_forces):
        ax_f.plot(record.t, record.f[:, k], label=names[k])
    for k in range(record.n_dof):
        ax_x.plot(record.t, record.x[:, k] * 1e3, label=names[record.n_forces + k])
    ax_f.set_ylabel("force [N]")
    ax_x.set_ylabel("displacement [mm]")
    ax_x.set_xlabel("t [s]")
    for ax in (ax_f, ax_x):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(title or record.source)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_hilbert(result, path: str | os.PathLike[str], *, title: str | None = None) -> None:
    """Argand (Nyquist) diagram of F and H{F}, and magnitude and phase, over the band.

    Parameters
    ----------
    result : duffid.analysis.nonlinearity.NonlinearityResult
        Result of :func:`duffid.analysis.nonlinearity.analyse` (holds the FRF and transforms).
    path : path
        PNG file to write.
    """
    frf = result.frf
    inside = frf.in_band
    f, F = frf.frequency[inside], frf.response[inside]
    curves = {"F": F, "H{F} corrected": result.transform[inside],
              "H{F} uncorrected": result.transform_uncorrected[inside]}
    fig = Figure(figsize=(11, 4.5))
    ax_n = fig.add_subplot(1, 2, 1)
    ax_m = fig.add_subplot(2, 2, 2)
    ax_p = fig.add_subplot(2, 2, 4, sharex=ax_m)
    for (label, values), style in zip(curves.items(), ("-", "--", ":")):
        ax_n.plot(values.real, values.imag, style, label=label)
        ax_m.semilogy(f, np.abs(values), style, label=label)
        ax_p.plot(f, np.degrees(np.angle(values)), style, label=label)
    ax_n.set_xlabel("Re [m/N]")
    ax_n.set_ylabel("Im [m/N]")
    ax_n.set_aspect("equal", adjustable="datalim")
    ax_n.legend(fontsize=8)
    ax_m.set_ylabel("|F| [m/N]")
    ax_p.set_ylabel("phase [deg]")
    ax_p.set_xlabel("f [Hz]")
    for ax in (ax_n, ax_m, ax_p):
        ax.grid(alpha=0.3)
    fig.suptitle(title or f"{result.source}: eta = {result.eta:.5f} "
                          f"(uncorrected {result.eta_uncorrected:.5f}), {result.verdict}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_eta_vs_amplitude(series, path: str | os.PathLike[str], *, threshold: float = 0.9,
                          title: str | None = None) -> None:
    """``eta`` and the Hilbert distortion vs excitation amplitude (paper Figures 6 and 11).

    Parameters
    ----------
    series : mapping of str to list of NonlinearityResult
        One curve per label (a plant, or a sweep rate), drawn in order of amplitude; each
        point's marker shows its verdict (filled: nonlinear, open: dominantly linear,
        cross: cannot tell).
    path : path
        PNG file to write.
    threshold : float
        The paper's eta criterion, drawn as a line.
    """
    from ..analysis.verdict import D_LINEAR_DB, D_NONLINEAR_DB

    fig = Figure(figsize=(10, 4))
    ax, ax_d = fig.subplots(1, 2)
    markers = {"nonlinear": dict(marker="o"), "dominantly linear": dict(marker="o", mfc="none"),
               "cannot tell": dict(marker="x")}
    for k, (label, results) in enumerate(series.items()):
        ordered = sorted(results, key=lambda r: r.amplitude)
        amps = [r.amplitude for r in ordered]
        color = f"C{k % 10}"
        ax.plot(amps, [r.eta for r in ordered], "-", color=color, label=f"{label} (corrected)")
        ax.plot(amps, [r.eta_uncorrected for r in ordered], ":", color=color, label=f"{label} (uncorrected)")
        ax_d.plot(amps, [r.distortion_db for r in ordered], "-", color=color, label=label)
        for r in ordered:
            style = markers.get(r.verdict, markers["cannot tell"])
            ax.plot([r.amplitude], [r.eta], ls="none", color=color, **style)
            ax_d.plot([r.amplitude], [r.distortion_db], ls="none", color=color, **style)
    ax.axhline(threshold, color="r", lw=0.8, ls="--", label=f"paper's threshold {threshold}")
    ax_d.axhline(D_NONLINEAR_DB, color="r", lw=0.8, ls="--", label=f"nonlinear from {D_NONLINEAR_DB:g} dB (above noise)")
    ax_d.axhline(D_LINEAR_DB, color="g", lw=0.8, ls="--", label=f"linear up to {D_LINEAR_DB:g} dB")
    ax.set_ylabel("eta")
    ax_d.set_ylabel("Hilbert distortion D [dB]")
    for a in (ax, ax_d):
        a.set_xlabel("excitation amplitude [N]")
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle(title or "Hilbert-transform nonlinearity index (filled: nonlinear, open: linear, x: cannot tell)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_closed_loop(result, path: str | os.PathLike[str], *, title: str | None = None) -> None:
    """Four panels of a closed loop (:class:`duffid.control.closed_loop.LoopResult`).

    Response (tracked position, reference, reference model, baseline), control force with
    its limit (the step before the switch is the identification excitation), relative
    error of the estimates vs time (log scale) and tracking error of both runs.

    Parameters
    ----------
    result : LoopResult
        Outcome of :func:`duffid.control.closed_loop.run_loop`.
    path : path
        PNG file to write.
    title : str, optional
        Figure title (default: the loop's title).
    """
    case = result.case
    a, b = result.adaptive, result.baseline
    unit, scale = case.position_unit
    funit, fscale = case.force_unit
    t = a.time
    fig = Figure(figsize=(9, 11))
    axes = fig.subplots(4, 1, sharex=True)
    ax = axes[0]
    ax.plot(t, case.reference(t) * scale, "k--", lw=0.9, label="reference r")
    ax.plot(t, a["controller.x_ref"] * scale, color="0.6", lw=0.9, label="desired trajectory (controller)")
    ax.plot(b.time, b[f"plant.{case.tracked}"] * scale, color="tab:red", lw=0.9, alpha=0.8,
            label=f"baseline ({case.mismatch:.0%} mismatch)")
    ax.plot(t, a[f"plant.{case.tracked}"] * scale, color="tab:blue", lw=1.1, label="adaptive")
    ax.set_ylabel(f"{case.tracked} [{unit}]")
    ax.legend(loc="best", fontsize=8)
    ax = axes[1]
    ax.plot(b.time, b["controller.f"] * fscale, color="tab:red", lw=0.8, alpha=0.8, label="baseline")
    ax.plot(t, a["controller.f"] * fscale, color="tab:blue", lw=1.0, label="adaptive")
    for sign in (1, -1):
        ax.axhline(sign * case.force_limit * fscale, color="k", ls=":", lw=0.8)
    ax.set_ylabel(f"{case.force} [{funit}]")
    ax.legend(loc="best", fontsize=8)
    ax = axes[2]
    for p in case.truth:
        estimate, true = a[f"estimator.{p}_hat"], case.true_values(p, t)
        error = np.full_like(estimate, np.nan)
        finite = np.isfinite(estimate)
        error[finite] = np.maximum(np.abs(estimate[finite] - true[finite]) / np.abs(true[finite]) * 100.0, 1e-6)
        ax.semilogy(t, error, lw=1.0, label=case.labels.get(p, p))
    ax.axhline(0.5, color="k", ls=":", lw=0.8)
    ax.set_ylabel("|estimate error| [%]")
    ax.legend(loc="best", fontsize=8, ncol=4)
    ax = axes[3]
    for run, color in (("baseline", "tab:red"), ("adaptive", "tab:blue")):
        time, error = result.tracking_error(run)
        after = time >= result.switch_time
        ax.plot(time[after], error[after] * scale, color=color, lw=0.9,
                label=f"{run}: RMS {result.tracking_rms[run] * scale:.4g} {unit}")
    t_from = result.switch_time + case.settle_after
    ax.axvline(t_from, color="0.5", ls=":", lw=0.8)
    time, error = result.tracking_error("baseline")
    span = np.max(np.abs(error[time >= t_from])) * scale
    if np.isfinite(span) and span > 0:  # zoom on the compared interval, not the switch transient
        ax.set_ylim(-1.5 * span, 1.5 * span)
    ax.set_ylabel(f"{case.tracked} - r [{unit}]")
    ax.set_xlabel("t [s]")
    ax.legend(loc="best", fontsize=8)
    for ax in axes:
        ax.axvline(result.switch_time, color="g", lw=0.8, alpha=0.7)
        ax.grid(alpha=0.3)
    fig.suptitle(title or f"{case.title}\nswitch to control at {result.switch_time:.3f} s (green)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_payload(result, path: str | os.PathLike[str]) -> None:
    """A payload run (:class:`duffid.control.closed_loop.LoopResult` with ``payload``): tracking
    error of both runs and the mass the estimator reports, coloured by its status.

    The top panel shows ``|x - r|`` (log scale) with the RMS of each phase; the bottom one
    the published mass, the true mass, and the estimator's status of ``m``. Vertical lines:
    payload (black), ``changed`` flag (orange), re-publication (green), controller
    re-adapted (blue).

    Parameters
    ----------
    result : LoopResult
        Outcome of :func:`duffid.control.closed_loop.run_loop` on a case with a payload.
    path : path
        PNG file to write.
    """
    from ..identification.engine import STATUSES

    case, r = result.case, result.payload
    if r is None:
        raise ValueError(f"{case.name} has no payload")
    unit, scale = case.position_unit
    a = result.adaptive
    t = a.time
    fig = Figure(figsize=(9, 7.5))
    axes = fig.subplots(2, 1, sharex=True)
    ax = axes[0]
    for run, color in (("baseline", "tab:red"), ("adaptive", "tab:blue")):
        time, error = result.tracking_error(run)
        after = time >= result.switch_time
        rms = ", ".join(f"{phase} {value * scale:.3g}" for phase, value in r.tracking_rms[run].items())
        ax.semilogy(time[after], np.maximum(np.abs(error[after]) * scale, 1e-9 * scale), color=color, lw=0.8,
                    label=f"{run} (RMS {unit}: {rms})")
    for phase, (start, end) in r.intervals.items():
        if math.isfinite(start):
            ax.axvspan(start, end, color={"before": "0.92", "transient": "#fde8d8", "recovered": "#e2f0d9"}[phase],
                       zorder=0)
    ax.set_ylabel(f"|{case.tracked} - r| [{unit}]")
    ax.legend(loc="lower left", fontsize=8)
    ax = axes[1]
    ax.plot(t, case.true_values("m", t), "k--", lw=1.0, label="true m")
    status = a["estimator.m_status"]
    ax.plot(t, a["estimator.m_hat"], color="tab:blue", lw=1.5, label="m published (NaN while withdrawn)")
    ax.set_ylabel("m [kg]")
    twin = ax.twinx()
    twin.step(t, status, where="post", color="tab:orange", lw=0.8, alpha=0.7)
    twin.set_yticks(range(len(STATUSES)), STATUSES, fontsize=7)
    twin.set_ylim(-0.5, len(STATUSES) - 0.5)
    twin.set_ylabel("status of m (orange)")
    ax.legend(loc="upper left", fontsize=8)
    ax.set_xlabel("t [s]")
    for axis in axes:
        for time, color in ((r.payload.time, "k"), (r.detected, "tab:orange"), (r.republished, "tab:green"),
                            (r.readapted, "tab:blue")):
            if math.isfinite(time):
                axis.axvline(time, color=color, lw=0.8, ls=":")
        axis.grid(alpha=0.3)
    def at(time: float) -> str:
        return f"{time:.3f} s" if math.isfinite(time) else "never"

    fig.suptitle(f"{case.title}\npayload at {r.payload.time:g} s, changed at {at(r.detected)}, "
                 f"m re-published at {at(r.republished)}, controller re-adapted at {at(r.readapted)}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_silverbox(result: SilverboxResult, path: str | os.PathLike[str]) -> None:
    """Measured vs simulated output and the simulation errors, per test record (PNG).

    Columns: ``arrow_full`` (its no-extrapolation part ends at the dashed line) and
    ``multisine_test``. Rows: the whole record, a 0.25 s zoom around the largest error
    and the simulation errors of each method.
    """
    names = [n for n in TEST_RECORDS if n != "arrow_no_extrapolation"]
    fig = Figure(figsize=(7 * len(names), 8.5))
    axes = fig.subplots(3, len(names), squeeze=False)
    methods = [m for m in ("algebraic", "refined") if m in result.simulations[names[0]]]
    for col, name in enumerate(names):
        sims = result.simulations[name]
        measured = 1e3 * sims["measured"]
        t = np.arange(len(measured)) / FS
        best = methods[-1]
        errors = {m: 1e3 * sims[m] - measured for m in methods}
        for err in errors.values():
            err[:SKIP] = np.nan
        whole, zoom, bottom = axes[:, col]
        whole.plot(t, measured, lw=0.4, color="k", label="measured")
        whole.plot(t, 1e3 * sims[best], lw=0.4, color="C1", alpha=0.6, label=f"simulated ({best})")
        centre = int(np.nanargmax(np.abs(errors[best])))
        span = slice(max(centre - int(0.125 * FS), 0), centre + int(0.125 * FS))
        zoom.plot(t[span], measured[span], lw=1.2, color="k", label="measured")
        for i, method in enumerate(methods):
            zoom.plot(t[span], 1e3 * sims[method][span], lw=0.9, ls="--", color=f"C{i}", label=method)
            rms = result.rms_mV[name][method]
            bottom.plot(t, errors[method], lw=0.4, color=f"C{i}", alpha=0.8,
                        label=f"{method}: RMS {rms:.3f} mV" if rms is not None else method)
        whole.axvspan(t[span][0], t[span][-1], color="C3", alpha=0.3)
        if name == "arrow_full":
            for ax in (whole, bottom):
                ax.axvline(ARROW_NO_EXTRAPOLATION / FS, color="gray", ls="--", lw=0.8)
        whole.set_title(name)
        whole.set_ylabel("output V2 [mV]")
        zoom.set_ylabel("zoom: largest error [mV]")
        bottom.set_ylabel("simulation error [mV]")
        bottom.set_xlabel("t [s]")
        zoom.set_xlabel("t [s]")
        for ax in (whole, zoom, bottom):
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8, loc="upper left")
    fig.suptitle("Silverbox: simulated vs measured output (dashed: end of the no-extrapolation part)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def plot_discovery_residual(found, record: Record, path: str | os.PathLike[str]) -> None:
    """The force residual of :func:`duffid.identification.discover.discover`'s best equation
    against the displacement and the velocity (:func:`~duffid.identification.discover.residual_shape`).

    Parameters
    ----------
    found : Discovery
        The search's outcome.
    record : Record
        The record it searched.
    path : path
        PNG file to write.
    """
    from ..identification.discover import residual_shape

    shape = found.residual or residual_shape(record, found.best.model, found.best.identification.estimates)
    x, v, r = (np.asarray(shape[k]) for k in ("x", "v", "residual"))
    fig = Figure(figsize=(10, 4.5))
    axes = fig.subplots(1, 2, sharey=True)
    for ax, data, label in ((axes[0], x, "x [m]"), (axes[1], v, "dx/dt [m/s]")):
        ax.scatter(data, r, s=2, c=np.sign(v), cmap="coolwarm", alpha=0.6)
        ax.set_xlabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("force residual [N] (red: moving up, blue: down)")
    fig.suptitle(f"{found.best.equation}\nresidual {shape['rms']:.3g} N RMS: {shape['shape']} "
                 f"({100 * shape['explained']:.0f} % of it)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
