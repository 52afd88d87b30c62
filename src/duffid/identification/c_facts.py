"""The facts the C estimator core shares with Python, in one place.

The core's limits (the maxima of a model description), its return codes, the statuses of a
parameter and the publication constants of :mod:`duffid.identification.engine` are defined
here (or read from the engine, their home) and written as the C header ``duffid_facts.h``
(:func:`c_header`; ``make generated`` rewrites the file, ``tests/test_c_facts.py`` checks it is
current). The C sources include that header instead of restating the numbers, and
:mod:`duffid.identification.c_core` reads the same tables.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..models.registry import GENERATED_MODEL_CODE, REGISTRY
from . import buffered, engine, regressors, row_noise

__all__ = ["Fact", "LIMITS", "RETURN_CODES", "MODEL_CODES", "PUBLICATION", "QUADRATURE", "C_HEADER_NAME", "c_header",
           "limit", "return_code"]

#: File name of the generated header (in ``fmus/estimator``).
C_HEADER_NAME = "duffid_facts.h"


@dataclass(frozen=True)
class Fact:
    """One named number of the C core: its C macro, value and meaning."""

    macro: str
    value: int | float
    meaning: str


#: The maxima of a model description (every array of the core is sized by them), by short name.
LIMITS: dict[str, Fact] = {f.macro.removeprefix("DUFFID_").lower(): f for f in (
    Fact("DUFFID_MAX_DOF", 6, "displacements per sample"),
    Fact("DUFFID_MAX_FORCES", 6, "forces per sample"),
    Fact("DUFFID_MAX_PARAMS", 40, "parameters of a model"),
    Fact("DUFFID_MAX_CHANNELS", 24, "distinct channels"),
    Fact("DUFFID_MAX_UNKNOWNS", 16, "unknowns of one block"),
    Fact("DUFFID_MAX_BLOCKS", 6, "blocks (equations or groups of equations solved together)"),
    Fact("DUFFID_MAX_PARTS", 6, "equations of one block"),
    Fact("DUFFID_MAX_TERMS", 64, "terms of one block"),
    Fact("DUFFID_MAX_RULES", 8, "scale rules of one unforced block"),
    Fact("DUFFID_MAX_SOURCES", 6, "combination and share sources of one parameter"),
    Fact("DUFFID_MAX_LINEAR", 96, "non-zero coefficients of the linear M or K map"),
    Fact("DUFFID_MAX_DERIVATIVE", 2, "highest derivative order of a term"),
    Fact("DUFFID_NAME_SIZE", 24, "bytes of a parameter name, with its terminating 0"),
    Fact("DUFFID_SIGNATURE_SIZE", 40, "bytes of a model's signature, with its terminating 0"),
    Fact("DUFFID_MAX_ROWS", 17, "rows per window of the robust method (n_rows)"),
    Fact("DUFFID_MAX_ROW_STRIDE", 4096, "samples between the rows of a deferred run (duffid_defer_solutions)"),
)}

#: Return codes of every core function that can fail, by short name.
RETURN_CODES: dict[str, Fact] = {f.macro.removeprefix("DUFFID_").lower(): f for f in (
    Fact("DUFFID_OK", 0, "success"),
    Fact("DUFFID_ERR_ARGUMENT", -1, "NULL pointer or wrong memory size"),
    Fact("DUFFID_ERR_CONFIG", -2, "invalid configuration, see the message buffer"),
    Fact("DUFFID_ERR_SAMPLE", -3, "a NaN or infinite sample; the state is unchanged"),
)}

#: The models the core describes itself, and the code of a generated description (from the
#: model registry; a code shared by several models is named after the first, e.g. the circuit
#: runs DUFFID_DUFFING1's description).
MODEL_CODES: tuple[Fact, ...] = (
    *{e.c_code: Fact(f"DUFFID_{name.upper()}", e.c_code, f"model {name}: {e.description}")
      for name, e in reversed(list(REGISTRY.items())) if e.c_code is not None}.values(),
    Fact("DUFFID_GENERATED", GENERATED_MODEL_CODE, "a model described by the generated file compiled in"),
)

#: The publication rules' constants of the online identifier (their home is the engine).
PUBLICATION: tuple[Fact, ...] = (
    *(Fact(f"DUFFID_STATUS_{name.upper().replace(' ', '_')}", code, f"status: {name}")
      for code, name in enumerate(engine.STATUSES)),
    Fact("DUFFID_MIN_SHARE", engine.MIN_SHARE, "a term below this share of the force balance is not excited"),
    Fact("DUFFID_LOSS_FACTOR", engine.LOSS_FACTOR, "lost above this many times max_uncertainty for settle s"),
    Fact("DUFFID_CHANGE_WINDOWS", engine.CHANGE_WINDOWS, "change test: default memory of the recent estimate in windows"),
    Fact("DUFFID_CHANGE_SURPRISE", engine.CHANGE_SURPRISE,
         "change test: a window's prediction error this many times the accumulated rows' restarts the recent estimate"),
    Fact("DUFFID_CHANGE_DRIFT_SHARE", engine.CHANGE_DRIFT_SHARE,
         "change test: a departure of this share of the threshold beyond the band, lasting the recent memory, is a drift"),
    Fact("DUFFID_CHANGE_ALONE_SHARE", engine.CHANGE_ALONE_SHARE,
         "change test: an unknown counts while changing it alone gains this share of the recent fit's prediction gain"),
    Fact("DUFFID_MAX_LINE_UNKNOWNS", engine.MAX_LINE_UNKNOWNS,
         "change test: unknowns of a block whose departed unknowns are lines in time, with their rates, at most"),
    Fact("DUFFID_DRIFT_SIGMAS", engine.DRIFT_SIGMAS,
         "change test: the drift probe's rate beyond this many standard errors is a drift"),
    Fact("DUFFID_DRIFT_BIAS_SIGMAS", engine.DRIFT_BIAS_SIGMAS,
         "change test: the drift probe's rate beyond this many standard errors biases the constants"),
    Fact("DUFFID_WINDOW_EQUATIONS", engine.WINDOW_EQUATIONS,
         "independent equations a window's length of accumulated rows counts for in their degrees of freedom"),
    Fact("DUFFID_WINDOW_INFLATION", engine.WINDOW_INFLATION,
         "the largest factor by which the window equations' degrees of freedom raise a standard error"),
    Fact("DUFFID_BATCH_WINDOWS", engine.BATCH_WINDOWS,
         "the batch-means errors' blocks of the rows' scores: this many windows' samples each"),
    Fact("DUFFID_BUFFERED_CHECK_SHARE", buffered.CHECK_SHARE,
         "buffered: a window's estimate against the one of this share of its first coefficient equations"),
    Fact("DUFFID_OFFSET_SIGMAS", engine.OFFSET_SIGMAS,
         "offset probe: a constant force beyond this many standard errors that moves a value keeps it unpublished"),
    Fact("DUFFID_FORCE_VARIATION", engine.FORCE_VARIATION,
         "offset probe: only while the rows' right-hand side varies by this share of its constant part"),
    Fact("DUFFID_GROWTH_STEADY", engine.GROWTH_STEADY,
         "a growing window's estimate steady while the window grew by this share"),
    Fact("DUFFID_MIN_SAMPLES", engine.MIN_SAMPLES, "samples before any solution is identified"),
    Fact("DUFFID_OUTLIER_SIGMAS", engine.OUTLIER_SIGMAS, "outlier: robust standard deviations from the quadratic"),
    Fact("DUFFID_OUTLIER_RANGE", engine.OUTLIER_RANGE, "outlier: never less than this share of the range covered"),
    Fact("DUFFID_OUTLIER_MEMORY", engine.OUTLIER_MEMORY, "outlier: samples of the robust deviation's memory"),
    Fact("DUFFID_JUMP_FACTOR", engine.JUMP_FACTOR, "force jump: a change this many times the running mean change"),
    Fact("DUFFID_JUMP_RANGE", engine.JUMP_RANGE, "force jump: never less than this share of the largest force seen"),
    Fact("DUFFID_MIN_WINDOW_PERIODS", engine.MIN_WINDOW_PERIODS, "the auto window's longest length holds at least this many natural periods"),
    Fact("DUFFID_MIN_UNCHECKED_SAMPLES", engine.MIN_UNCHECKED_SAMPLES, "... while a mass is not excited, the window holds at least this many samples"),
    Fact("DUFFID_JUMP_ISOLATION", engine.JUMP_ISOLATION, "force jump: the next change is at most this share of it"),
    Fact("DUFFID_JUMP_ERROR", engine.JUMP_ERROR, "force jump: a row errs by up to this share of the jump times the interval"),
    Fact("DUFFID_NOISE_SHARE", row_noise.NOISE_SHARE,
         "rows' noise: no solution where the displacement's noise carries this share of the rows' energy in some direction"),
    Fact("DUFFID_NOISE_SEED", row_noise.NOISE_SEED, "rows' noise: the seed of its generator (xorshift32)"),
    Fact("DUFFID_RATE_NOISE", engine.RATE_NOISE,
         "quadrature: the unknowns' change with the rows at half the rate beyond this many standard errors is a bias"),
)


#: The quadrature's facts (their home is :mod:`duffid.identification.regressors`).
QUADRATURE: tuple[Fact, ...] = (
    Fact("DUFFID_GREGORY_POINTS", regressors.GREGORY_POINTS,
         "Gregory's rule: corrected samples at each end of a window (fewer where the ends meet)"),
)


def _gregory_table() -> list[str]:
    """``DUFFID_GREGORY_END(R)``: row ``p - 1`` holds the corrections of ``p`` points
    (zero-padded), each literal wrapped in ``R`` (the core's real-constant macro)."""
    P = regressors.GREGORY_POINTS
    rows = []
    for p in range(1, P + 1):
        values = [f"R({_literal(float(d))})" for d in regressors.gregory_end(p)] + ["R(0.0)"] * (P - p)
        rows.append("    {" + ", ".join(values) + "}")
    return ["/* Gregory's end corrections c_i - 1 of p points (row p - 1; regressors.gregory_end) */",
            "#define DUFFID_GREGORY_END(R) { \\", *(r + (", \\" if i + 1 < P else " \\") for i, r in enumerate(rows)),
            "}", ""]


def limit(name: str) -> int:
    """The value of a limit by short name (``"max_params"``)."""
    return int(LIMITS[name].value)


def return_code(name: str) -> int:
    """The value of a return code by short name (``"err_sample"``)."""
    return int(RETURN_CODES[name].value)


def _literal(value: int | float) -> str:
    if isinstance(value, int):
        return f"({value})" if value < 0 else str(value)
    text = repr(float(value))
    return text if ("." in text or "e" in text) else text + ".0"


def c_header() -> str:
    """The text of ``duffid_facts.h``."""
    def block(title: str, facts) -> list[str]:
        lines = [f"/* {title} */"]
        for f in facts:
            lines.append(f"#define {f.macro} {_literal(f.value)} /* {f.meaning} */")
        return lines + [""]

    lines = [
        "/* The facts the estimator core shares with Python: GENERATED by",
        " * duffid.identification.c_facts (their single source); do not edit. `make generated`",
        " * rewrites it; tests/test_c_facts.py checks it is current. */",
        "#ifndef DUFFID_FACTS_H",
        "#define DUFFID_FACTS_H",
        "",
        *block("Fixed maxima of a model description (every array of the engine is sized by them).",
               LIMITS.values()),
        *block("Return codes: every function that can fail returns one of these.", RETURN_CODES.values()),
        *block("Models (duffid.models.registry).", sorted(MODEL_CODES, key=lambda f: f.value)),
        *block("Statuses of a parameter and the publication rules' constants "
               "(duffid.identification.engine).", PUBLICATION),
        *block("Quadrature (duffid.identification.regressors).", QUADRATURE),
        *_gregory_table(),
        "#endif /* DUFFID_FACTS_H */",
        "",
    ]
    return "\n".join(lines)
