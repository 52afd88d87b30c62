"""Plots written to files (matplotlib, non-interactive Agg backend)."""
from __future__ import annotations

import os
from typing import Mapping

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .identification import Identification  # noqa: E402
from .record import Record  # noqa: E402

__all__ = ["plot_estimates", "plot_record"]


def plot_estimates(result: Identification, path: str | os.PathLike[str], *,
                   truth: Mapping[str, float] | None = None,
                   series: Mapping[str, np.ndarray] | None = None, title: str | None = None) -> None:
    """Estimates vs time, one panel per parameter (like the paper's Figures 8, 12, 13).

    Parameters
    ----------
    result : Identification
        Result of :func:`duffid.identify`.
    path : path
        PNG file to write.
    truth : mapping, optional
        True values drawn as dashed lines.
    series : mapping, optional
        Extra curves to plot instead of ``result.history`` (e.g. ratios ``b2/m2``).
    title : str, optional
        Figure title.
    """
    curves = dict(series) if series is not None else dict(result.history)
    n = len(curves)
    cols = 2 if n > 3 else 1
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(6 * cols, 2.2 * rows), sharex=True, squeeze=False)
    for ax, (name, values) in zip(axes.flat, curves.items()):
        ax.plot(result.t, values, lw=1.2, label="estimate")
        if truth is not None and name in truth:
            ax.axhline(truth[name], color="k", ls="--", lw=0.8, label="truth")
            finite = values[np.isfinite(values)]
            if finite.size:  # zoom on the truth: early transients would hide the result
                span = max(abs(truth[name]) * 0.2, 1e-12)
                ax.set_ylim(truth[name] - span, truth[name] + span)
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
    plt.close(fig)


def plot_record(record: Record, path: str | os.PathLike[str], *, title: str | None = None) -> None:
    """Forces and displacements of a record vs time."""
    fig, (ax_f, ax_x) = plt.subplots(2, 1, figsize=(7, 4.5), sharex=True)
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
    plt.close(fig)
