"""The nonlinearity verdict: "dominantly linear", "nonlinear" or "cannot tell", with its reasons.

The evidence, per record: the paper's index ``eta`` and the Hilbert distortion ``D`` of its
FRF, each against the noise floor of ``D`` (what the record's measurement noise alone
would give) and, for the ``h1`` estimator, the share of the response power that is not
linearly related to the force beyond what the noise explains (a random force linearises
a nonlinear plant's FRF, so ``D`` alone cannot see it). Across records of one plant at
different amplitudes: the homogeneity test, the change of the FRF with amplitude.

"dominantly linear" claims that the cubic (or other) part of the restoring force stays
under about 10 % of the linear part over the record's range; "nonlinear" that a
distortion beyond the noise was found. Every threshold lives here, set by the simulation
study of ``benchmarks/nonlinearity.py`` (which prints them with its table).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from .frf import FRF

__all__ = [
    "ETA_LINEAR",
    "ETA_NONLINEAR",
    "D_LINEAR_DB",
    "D_NONLINEAR_DB",
    "FLOOR_MARGIN_DB",
    "INCOHERENT_NONLINEAR",
    "HOMOGENEITY_LINEAR_DB",
    "HOMOGENEITY_NONLINEAR_DB",
    "HOMOGENEITY_MIN_RATIO",
    "SHARE_LINEAR",
    "VERDICTS",
    "Decision",
    "thresholds",
    "distortion_floor",
    "decide",
    "homogeneity",
    "decide_group",
]

VERDICTS = ("dominantly linear", "nonlinear", "cannot tell")

# ---- thresholds, set by the simulation study of benchmarks/nonlinearity.py (1-DOF plants, linear,
# ---- hardening and softening with a cubic share of 3, 10 and 25 % at the peak, sweep + ring-down,
# ---- random force, stepped sines, SNR 60/40/30 dB on force and displacement): no wrong confident
# ---- verdict in 378 records. Measured there: a linear plant's D lies within 3 dB of its noise
# ---- floor; a 1 Hz/s sweep reads D = -38, -28, -21 dB for shares of 3, 10, 25 %, stepped sines
# ---- -29, -20, -15 dB; under a random force D stays near -32 dB whatever the share.
#: The paper's criterion: ``eta >= 0.9`` reads "dominantly linear"; below, with D beyond its
#: noise floor, "nonlinear".
ETA_NONLINEAR = 0.9
#: "dominantly linear" needs ``eta`` at least this (eta ~ 1 - d^2 for a relative distortion d).
ETA_LINEAR = 0.9999
#: "dominantly linear" needs the Hilbert distortion at most this [dB]: 7 dB below what a 3 %
#: share gives under a sweep, 17 dB below a 10 % share.
D_LINEAR_DB = -45.0
#: "nonlinear" needs the Hilbert distortion at least this [dB] ...
D_NONLINEAR_DB = -50.0
#: ... and at least this far above the noise floor of D [dB] (a linear plant: within 3 dB).
FLOOR_MARGIN_DB = 10.0
#: ``h1``: "nonlinear" needs at least this share of the in-band response power not linearly
#: related to the force beyond what the noise and the segments' resolution explain (and 10x
#: the noise's part, and as much as the resolution's part, whose estimate is only good to
#: tens of percent: a linear plant's 4 s segments left 0.9 % of a 4.5 % part). A random force linearises the plant: alone, an ``h1`` record never
#: reads "dominantly linear" (the homogeneity test of several amplitudes can).
INCOHERENT_NONLINEAR = 3e-3
#: Homogeneity: the FRF at the largest amplitude differs from that at the smallest by at
#: least this [dB] (and the noise floor by FLOOR_MARGIN_DB): "nonlinear" (the study's random
#: forces at 1/3 N and 1 N: -15 dB for a 25 % share, a linear plant its noise floor) ...
HOMOGENEITY_NONLINEAR_DB = -35.0
#: ... at most this: supports "dominantly linear" (when the amplitudes differ by HOMOGENEITY_MIN_RATIO).
HOMOGENEITY_LINEAR_DB = -35.0
#: The amplitudes compared must differ by this factor for the test to support linearity.
HOMOGENEITY_MIN_RATIO = 2.0
#: What "dominantly linear" claims: a nonlinear share of the restoring force under this.
SHARE_LINEAR = 0.10


def thresholds() -> dict[str, float]:
    """Every threshold of the decision, by name (printed with the verdict and by the benchmark)."""
    return {"ETA_NONLINEAR": ETA_NONLINEAR, "ETA_LINEAR": ETA_LINEAR, "D_LINEAR_DB": D_LINEAR_DB,
            "D_NONLINEAR_DB": D_NONLINEAR_DB, "FLOOR_MARGIN_DB": FLOOR_MARGIN_DB,
            "INCOHERENT_NONLINEAR": INCOHERENT_NONLINEAR,
            "HOMOGENEITY_LINEAR_DB": HOMOGENEITY_LINEAR_DB, "HOMOGENEITY_NONLINEAR_DB": HOMOGENEITY_NONLINEAR_DB,
            "HOMOGENEITY_MIN_RATIO": HOMOGENEITY_MIN_RATIO, "SHARE_LINEAR": SHARE_LINEAR}


@dataclass
class Decision:
    """A verdict and what it rests on.

    Attributes
    ----------
    verdict : str
        One of :data:`VERDICTS`.
    reasons : list of str
        What the verdict rests on, or why the record cannot support one, in words.
    evidence : dict
        The figures compared with the thresholds.
    """

    verdict: str
    reasons: list[str] = field(default_factory=list)
    evidence: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``verdict``, ``reasons``, ``evidence`` (NaN as None)."""
        def clean(v: Any) -> Any:
            return None if isinstance(v, float) and not np.isfinite(v) else v
        return {"verdict": self.verdict, "reasons": list(self.reasons),
                "evidence": {k: clean(v) for k, v in self.evidence.items()}}


def _db(ratio: float) -> float:
    return float(10.0 * np.log10(ratio)) if ratio > 0 else float("-inf")


def distortion_floor(frf: FRF, lines: np.ndarray | None = None) -> float:
    """Noise floor of the Hilbert distortion [dB]: ``10 log10(2 sum var / sum |F|^2)`` over the band.

    Noise on the FRF is acausal: its Hilbert transform is uncorrelated with it, so
    ``|H{N} - N|^2`` averages ``2 |N|^2``. NaN when the FRF has no variance.
    """
    if frf.variance is None:
        return float("nan")
    inside = frf.in_band if lines is None else lines
    ref = float(np.sum(np.abs(frf.response[inside]) ** 2))
    return _db(2.0 * float(np.sum(frf.variance[inside])) / ref) if ref > 0 else float("nan")


def decide(eta: float, distortion_db: float, frf: FRF) -> Decision:
    """The verdict on one FRF: its record checks, then ``eta`` and ``D`` against the thresholds.

    Parameters
    ----------
    eta, distortion_db : float
        The index and the Hilbert distortion [dB] of ``frf``.
    frf : FRF
        The FRF with its variance, problems and checks.
    """
    floor = distortion_floor(frf)
    evidence: dict[str, Any] = {"eta": eta, "distortion_db": distortion_db, "floor_db": floor,
                                "estimator": frf.estimator}
    evidence.update({k: v for k, v in frf.checks.items() if k in ("incoherent", "incoherent_noise")})
    if frf.problems:
        return Decision("cannot tell", list(frf.problems), evidence)
    if not (np.isfinite(eta) and np.isfinite(distortion_db)):
        return Decision("cannot tell", ["the index could not be computed"], evidence)
    floor_known = np.isfinite(floor)
    above_floor = floor_known and distortion_db >= floor + FLOOR_MARGIN_DB
    floor_text = f"its noise floor {floor:.0f} dB" if floor_known else "an unknown noise floor"
    reasons: list[str] = []
    nonlinear = False
    if above_floor and distortion_db >= D_NONLINEAR_DB:
        nonlinear = True
        reasons.append(f"Hilbert distortion D = {distortion_db:.1f} dB, above {D_NONLINEAR_DB:g} dB and "
                       f"{distortion_db - floor:.0f} dB above {floor_text}"
                       + (f"; eta = {eta:.4f} < {ETA_NONLINEAR:g} (the paper's criterion)" if eta < ETA_NONLINEAR else ""))
    if frf.estimator == "h1":
        incoherent = frf.checks.get("incoherent", float("nan"))
        noise_part = frf.checks.get("incoherent_noise", 0.0)
        resolution = frf.checks.get("incoherent_resolution", float("nan"))
        explained = noise_part + (resolution if np.isfinite(resolution) else 0.0)
        excess = incoherent - explained
        evidence["incoherent_excess"] = excess
        figures = (f"{100 * incoherent:.2g} % of the response power in the band is not linearly related to the "
                   f"force; the measurement noise explains {100 * noise_part:.2g} % and the segments' resolution "
                   f"{100 * resolution:.2g} %")
        if np.isfinite(resolution) and excess >= max(INCOHERENT_NONLINEAR, 10.0 * noise_part, resolution):
            return Decision("nonlinear", reasons + [
                figures + f": the {100 * excess:.2g} % left (at least {100 * INCOHERENT_NONLINEAR:g} %, ten times the "
                "noise's part and as much as the resolution's means nonlinear) is the plant's own distortion, "
                "unless an unmeasured force acts on it"], evidence)
        evidence["linearised"] = True
        return Decision("cannot tell", [
            "a random force linearises the plant: H1 is its best linear approximation, causal whatever the "
            "nonlinearity, so one record cannot show that the plant is linear (" + figures + "): give records "
            "at two or more amplitudes (homogeneity test), or a sweep with a ring-down"], evidence)
    if nonlinear:
        return Decision("nonlinear", reasons, evidence)
    if distortion_db <= D_LINEAR_DB and eta >= ETA_LINEAR:
        reasons = [f"Hilbert distortion D = {distortion_db:.1f} dB at most {D_LINEAR_DB:g} dB and "
                   f"eta = {eta:.5f} at least {ETA_LINEAR:g}"]
        return Decision("dominantly linear", reasons, evidence)
    if not floor_known:
        why = (f"Hilbert distortion D = {distortion_db:.1f} dB, but the FRF carries no estimate of its noise "
               "(an FRF given without variance): 'nonlinear' needs D "
               f"{FLOOR_MARGIN_DB:g} dB above the noise floor")
    elif floor + FLOOR_MARGIN_DB > D_NONLINEAR_DB and distortion_db > D_LINEAR_DB:
        why = (f"the measurement noise alone gives D about {floor:.0f} dB, too close to the thresholds "
               f"({D_LINEAR_DB:g} dB for 'dominantly linear', {D_NONLINEAR_DB:g} dB and {FLOOR_MARGIN_DB:g} dB "
               "above the noise for 'nonlinear'): a cleaner or longer record, or more averages")
    else:
        why = (f"Hilbert distortion D = {distortion_db:.1f} dB (noise floor {floor:.0f} dB) and eta = {eta:.5f}: "
               f"'dominantly linear' needs D at most {D_LINEAR_DB:g} dB and eta at least {ETA_LINEAR:g}, "
               f"'nonlinear' D at least {D_NONLINEAR_DB:g} dB and {FLOOR_MARGIN_DB:g} dB above the noise")
    return Decision("cannot tell", [why], evidence)


def _common(frfs: Sequence[FRF]) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """Responses and variances of several FRFs on the grid of the first, over their common band."""
    lo = max(f.band[0] for f in frfs)
    hi = min(f.band[1] for f in frfs)
    grid = frfs[0].frequency[(frfs[0].frequency >= lo) & (frfs[0].frequency <= hi)]
    values, variances = [], []
    for f in frfs:
        values.append(np.interp(grid, f.frequency, f.response.real) + 1j * np.interp(grid, f.frequency, f.response.imag))
        var = f.variance if f.variance is not None else np.zeros(len(f.frequency))
        variances.append(np.interp(grid, f.frequency, np.where(np.isfinite(var), var, 1e300)))
    return grid, values, variances


def homogeneity(frfs: Sequence[FRF]) -> dict[str, float]:
    """The change of the FRF between the smallest and the largest amplitude.

    Returns
    -------
    dict
        ``change_db`` = ``10 log10(sum |F_max - F_min|^2 / sum |F_min|^2)`` over the common
        band, ``floor_db`` (the noise's share of it), ``ratio`` (largest over smallest
        amplitude) and ``lines`` (common lines); NaN values when the bands do not overlap.
    """
    ordered = sorted(frfs, key=lambda f: f.amplitude)
    low, high = ordered[0], ordered[-1]
    ratio = high.amplitude / low.amplitude if low.amplitude > 0 else float("inf")
    grid, (a, b), (va, vb) = _common([low, high])
    if len(grid) < 8:
        return {"change_db": float("nan"), "floor_db": float("nan"), "ratio": ratio, "lines": len(grid)}
    ref = float(np.sum(np.abs(a) ** 2))
    return {"change_db": _db(float(np.sum(np.abs(b - a) ** 2)) / ref),
            "floor_db": _db(float(np.sum(va + vb)) / ref), "ratio": ratio, "lines": len(grid)}


def decide_group(decisions: Sequence[Decision], frfs: Sequence[FRF]) -> Decision:
    """One verdict for several records of one plant: each record's, and the homogeneity test.

    "nonlinear" when a usable record or the homogeneity test says so; "dominantly linear"
    when every record says so and (with amplitudes at least :data:`HOMOGENEITY_MIN_RATIO`
    apart) the FRF does not change with amplitude; else "cannot tell".
    """
    usable = [(d, f) for d, f in zip(decisions, frfs) if not f.problems]
    reasons: list[str] = []
    evidence: dict[str, Any] = {"records": len(decisions), "usable": len(usable)}
    hom = None
    if len(usable) >= 2:
        hom = homogeneity([f for _, f in usable])
        evidence.update({f"homogeneity_{k}": v for k, v in hom.items()})
    nonlinear = [d for d, _ in usable if d.verdict == "nonlinear"]
    if nonlinear:
        reasons.append(f"{len(nonlinear)} of {len(decisions)} records show a nonlinear distortion")
    if hom is not None and np.isfinite(hom["change_db"]):
        changed = (hom["change_db"] >= HOMOGENEITY_NONLINEAR_DB
                   and hom["change_db"] >= hom["floor_db"] + FLOOR_MARGIN_DB)
        if changed:
            reasons.append(f"the FRF changes with amplitude: {hom['change_db']:.1f} dB between {hom['ratio']:.3g}x "
                           f"amplitudes (at least {HOMOGENEITY_NONLINEAR_DB:g} dB and {FLOOR_MARGIN_DB:g} dB above "
                           f"the noise's {hom['floor_db']:.0f} dB means nonlinear)")
            return Decision("nonlinear", reasons, evidence)
    if nonlinear:
        return Decision("nonlinear", reasons, evidence)
    if len(usable) < len(decisions):
        reasons.append(f"{len(decisions) - len(usable)} of {len(decisions)} records cannot be used (see each record)")
    linear_or_linearised = all(d.verdict == "dominantly linear" or d.evidence.get("linearised") for d, _ in usable)
    needs_homogeneity = any(d.evidence.get("linearised") for d, _ in usable)
    if usable and linear_or_linearised:
        informative = hom is not None and hom["ratio"] >= HOMOGENEITY_MIN_RATIO and np.isfinite(hom["change_db"])
        if not informative and not needs_homogeneity:
            reasons.append("each usable record is dominantly linear")
            return Decision("dominantly linear", reasons, evidence)
        if not informative:
            reasons.append(f"random-force records need the homogeneity test: amplitudes at least "
                           f"{HOMOGENEITY_MIN_RATIO:g}x apart")
            return Decision("cannot tell", reasons, evidence)
        if hom["change_db"] <= HOMOGENEITY_LINEAR_DB:  # noise only adds to the change: no floor needed
            reasons.append(("each usable record is dominantly linear, and " if not needs_homogeneity else "")
                           + f"the FRF changes by {hom['change_db']:.1f} dB (at most {HOMOGENEITY_LINEAR_DB:g} dB) "
                           f"over a {hom['ratio']:.3g}x amplitude range")
            return Decision("dominantly linear", reasons, evidence)
        reasons.append(f"the FRF changes by {hom['change_db']:.1f} dB with amplitude: more than "
                       f"{HOMOGENEITY_LINEAR_DB:g} dB, but not {FLOOR_MARGIN_DB:g} dB above the noise's "
                       f"{hom['floor_db']:.0f} dB")
    elif usable:
        reasons.append("not every usable record supports 'dominantly linear' (see each record)")
    return Decision("cannot tell", reasons or ["no record can be used"], evidence)
