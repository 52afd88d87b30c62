"""Tables and plots of a campaign's results.

Rows are grouped by the campaign's factors (the seeds are the samples of a group):

- ``identification``: per group the median and 90th percentile of ``|error|`` [%] of each
  parameter over the seeds, and with the checks how often each parameter was published;
  plot: the distribution of ``|error|`` per group, one panel per parameter;
- ``nonlinearity``: ``eta`` (corrected and not), ``D`` and the verdict per group; plot:
  ``eta`` vs amplitude, one curve per group of the other factors;
- ``cosim``: each metric per group (median, and range over the seeds); plot: each metric
  vs each numeric factor.

Failed tasks are counted per group and left out of the figures.
"""
from __future__ import annotations

import math
import os
from collections import defaultdict
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pyarrow as pa
from matplotlib.figure import Figure
from matplotlib.ticker import NullFormatter

from ..analysis.nonlinearity import LINEARITY_THRESHOLD
from .spec import CampaignSpec
from .plants import RESERVED

__all__ = ["summary_lines", "write_plots", "group_rows"]

_PER_TASK = ("seconds", "worker", "rows", "note", "band_low", "band_high")


def _factors(spec: CampaignSpec, table: pa.Table) -> list[str]:
    return [f for f in spec.factors if f != "seed" and f in table.column_names]


def _label(group: tuple[tuple[str, Any], ...]) -> str:
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in group) or "all"


def group_rows(table: pa.Table, spec: CampaignSpec) -> dict[tuple[tuple[str, Any], ...], list[dict[str, Any]]]:
    """Rows grouped by the values of the factors other than the seed, in the spec's order."""
    factors = _factors(spec, table)
    order = {t.id: i for i, t in enumerate(spec.tasks)}
    rows = sorted(table.to_pylist(), key=lambda r: order.get(r["task"], len(order)))
    groups: dict[tuple[tuple[str, Any], ...], list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        groups[tuple((f, row.get(f)) for f in factors)].append(row)
    return dict(groups)


def _values(rows: Sequence[dict[str, Any]], column: str) -> np.ndarray:
    return np.array([r[column] for r in rows if r.get("status") == "ok" and r.get(column) is not None], dtype=float)


def _metric_columns(table: pa.Table, spec: CampaignSpec) -> list[str]:
    skip = set(RESERVED) | set(spec.factors) | set(_PER_TASK)
    return [c for c in table.column_names if c not in skip and pa.types.is_floating(table.schema.field(c).type)]


def _cell(value: float, fmt: str = ".4g") -> str:
    return "-" if not np.isfinite(value) else format(value, fmt)


def summary_lines(table: pa.Table, spec: CampaignSpec) -> list[str]:
    """Printable tables of the results (see the module documentation)."""
    groups = group_rows(table, spec)
    w = max([36] + [len(_label(g)) + 2 for g in groups])
    lines = [f"{spec.name}: {table.num_rows} task(s), "
             f"{sum(r == 'ok' for r in table.column('status').to_pylist())} ok"]
    if spec.kind == "identification":
        parameters = [c[len("error_"):] for c in table.column_names if c.startswith("error_")]
        checked = any(c.startswith("status_") for c in table.column_names)
        lines.append("median |error| [%] over the seeds (90th percentile in brackets), runs without a value "
                     "(NaN) left out and counted" + ("; published: share of the runs that published the value"
                                                     if checked else ""))
        body = []
        for group, rows in groups.items():
            cells = []
            for p in parameters:
                errors = np.abs(_values(rows, f"error_{p}"))
                errors = errors[np.isfinite(errors)]
                cell = f"{_cell(np.median(errors) if len(errors) else math.nan, '.3g')} " \
                       f"[{_cell(np.percentile(errors, 90) if len(errors) else math.nan, '.3g')}]"
                if checked:
                    ok = [r for r in rows if r.get("status") == "ok"]
                    share = np.mean([r.get(f"status_{p}") == "published" for r in ok]) if ok else math.nan
                    cell += f" {_cell(100 * share, '.0f')}%"
                cells.append(cell)
            failed = sum(r.get("status") != "ok" for r in rows)
            missing = sum(r.get("status") == "ok" and not all(
                r.get(f"estimate_{p}") is not None and math.isfinite(r[f"estimate_{p}"]) for p in parameters)
                for r in rows)
            body.append((group, len(rows), failed, missing, cells))
        cw = max([len(p) for p in parameters] + [len(c) for *_, cells in body for c in cells]) + 2
        lines.append(f"{'group':<{w}}{'runs':>6}{'failed':>7}{'no value':>9}" + "".join(f"{p:>{cw}}" for p in parameters))
        for group, n, failed, missing, cells in body:
            lines.append(f"{_label(group):<{w}}{n:>6}{failed:>7}{missing:>9}" + "".join(f"{c:>{cw}}" for c in cells))
    elif spec.kind == "nonlinearity":
        w += 10  # room for the seed
        lines.append(f"{'group':<{w}}{'eta':>10}{'uncorr.':>10}{'D [dB]':>9}  verdict")
        for group, rows in groups.items():
            for row in rows:
                seed = f", seed={row['seed']}" if "seed" in row else ""
                if row.get("status") != "ok":
                    lines.append(f"{_label(group) + seed:<{w}}  failed: {row.get('error')}")
                    continue
                lines.append(f"{_label(group) + seed:<{w}}{_cell(row['eta'], '.5f'):>10}"
                             f"{_cell(row['eta_uncorrected'], '.5f'):>10}{_cell(row['distortion_db'], '.1f'):>9}"
                             f"  {row.get('verdict')}" + (f" ({row['note']})" if row.get("note") else ""))
    else:
        metrics = _metric_columns(table, spec)
        lines.append("median over the seeds [min, max]" if "seed" in spec.factors else "metrics")
        lines.append(f"{'group':<{w}}{'runs':>6}{'failed':>7}" + "".join(f"{m:>28}" for m in metrics))
        for group, rows in groups.items():
            cells = []
            for m in metrics:
                v = _values(rows, m)
                text = _cell(np.median(v)) if len(v) else "-"
                if len(v) > 1:
                    text += f" [{_cell(v.min())}, {_cell(v.max())}]"
                cells.append(f"{text:>28}")
            failed = sum(r.get("status") != "ok" for r in rows)
            lines.append(f"{_label(group):<{w}}{len(rows):>6}{failed:>7}" + "".join(cells))
    errors = [r for r in table.to_pylist() if r.get("status") != "ok"]
    for row in errors[:10]:
        lines.append(f"failed: {row['task']}: {row.get('error')}")
    if len(errors) > 10:
        lines.append(f"... and {len(errors) - 10} more failed task(s) (column 'error' of the results)")
    return lines


def _save(fig: Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def write_plots(table: pa.Table, spec: CampaignSpec, folder: str | os.PathLike[str]) -> list[Path]:
    """Write the campaign's plots (PNG) into ``folder``; their paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stem = spec.path.stem
    groups = group_rows(table, spec)
    written: list[Path] = []
    if spec.kind == "identification":
        parameters = [c[len("error_"):] for c in table.column_names if c.startswith("error_")]
        if not parameters:
            return written
        cols = 2 if len(parameters) > 1 else 1
        rows_n = math.ceil(len(parameters) / cols)
        fig = Figure(figsize=(5.5 * cols, 0.6 + 2.8 * rows_n))
        axes = np.atleast_1d(fig.subplots(rows_n, cols)).ravel()
        labels = [_label(g) for g in groups]
        for ax, p in zip(axes, parameters):
            data = [np.abs(_values(rows, f"error_{p}")) for rows in groups.values()]
            data = [d[np.isfinite(d)] for d in data]
            ax.boxplot([d if len(d) else [np.nan] for d in data], vert=False)
            ax.set_yticks(range(1, len(labels) + 1), labels, fontsize=7)
            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(NullFormatter())
            ax.set_xlabel(f"|error of {p}| [%]")
            ax.grid(alpha=0.3)
        for ax in axes[len(parameters):]:
            ax.set_visible(False)
        fig.suptitle(f"{spec.name}: error distributions per factor")
        written.append(_save(fig, folder / f"{stem}_errors.png"))
    elif spec.kind == "nonlinearity":
        others = [f for f in _factors(spec, table) if f != "amplitude"]
        curves: dict[str, list[tuple[float, float, float]]] = defaultdict(list)
        for row in table.to_pylist():
            if row.get("status") == "ok":
                label = _label(tuple((f, row.get(f)) for f in others))
                amplitude = row.get("amplitude", spec.tasks[0].settings.get("amplitude"))
                curves[label].append((float(amplitude), row["eta"], row["eta_uncorrected"]))
        fig = Figure(figsize=(6.5, 4))
        ax = fig.subplots()
        for label, points in curves.items():
            points.sort()
            a, eta, unc = (np.array(v, dtype=float) for v in zip(*points))
            line, = ax.plot(a, eta, "o-", label=f"{label} (corrected)")
            ax.plot(a, unc, "x:", color=line.get_color(), label=f"{label} (uncorrected)")
        ax.axhline(LINEARITY_THRESHOLD, color="r", lw=0.8, ls="--", label=f"threshold {LINEARITY_THRESHOLD}")
        ax.set_xlabel("excitation amplitude [N]")
        ax.set_ylabel("eta")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        ax.set_title(f"{spec.name}: eta vs amplitude")
        written.append(_save(fig, folder / f"{stem}_eta.png"))
    else:
        numeric = [f for f in spec.factors if f in table.column_names and f != "seed"
                   and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in spec.factors[f])]
        for metric in _metric_columns(table, spec):
            if not numeric:
                break
            fig = Figure(figsize=(5 * len(numeric), 3.8))
            axes = np.atleast_1d(fig.subplots(1, len(numeric)))
            ok = [r for r in table.to_pylist() if r.get("status") == "ok" and r.get(metric) is not None]
            for ax, factor in zip(axes, numeric):
                ax.plot([r[factor] for r in ok], [r[metric] for r in ok], "o", alpha=0.7)
                ax.set_xlabel(factor)
                ax.set_ylabel(metric)
                ax.grid(alpha=0.3)
            fig.suptitle(f"{spec.name}: {metric} vs parameter")
            written.append(_save(fig, folder / f"{stem}_{metric.replace('.', '_')}.png"))
    return written
