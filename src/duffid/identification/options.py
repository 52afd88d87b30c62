"""The options of the identifiers: one declarative schema, everything else from it.

:data:`OPTIONS` lists every option of the online methods (robust and paper) once: its name,
the methods that take it, its type and default, its valid range, its unit and what it
means, and how the C core codes it. :data:`BUFFERED_OPTIONS` does the same for the buffered
methods (one per orthogonal basis, paper section 4; Python only). An option name that both
families use (``window``, ``quadrature``, ``max_condition``, ``max_uncertainty``) is one
command-line flag whose help states each family's meaning and default. From the schema come

- the Python defaults and validation (:func:`default_options`, :func:`check_options`);
- the C header ``fmus/estimator/duffid_options.h`` (:func:`c_header`): the fields of
  ``duffid_config``, their defaults (``duffid_default_config``) and range checks
  (``duffid_check_config``), and the estimator FMUs' option parameters, as X-macro
  tables (tests/test_options.py checks the file is current; ``make generated`` rewrites it);
- the ctypes fields of :class:`duffid.identification.c_core.CConfig` (:func:`ctypes_fields`)
  and the Python-to-C coding (:func:`to_c`);
- the estimator FMUs' parameter tables (:func:`fmu_parameters`), C and pythonfmu;
- the ``duffid identify`` flags of every method (:func:`add_arguments`,
  :func:`add_shared_arguments`) and the options a parsed command line gives a method
  (:func:`options_from_arguments`).
"""
from __future__ import annotations

import argparse
import ctypes
import math
import numbers
from dataclasses import dataclass
from typing import Any, Mapping

from ..errors import InputError, OptionError
from .orthogonal import BASES, QUADRATURES

__all__ = ["Option", "OPTIONS", "BUFFERED_OPTIONS", "ONLINE_METHODS", "BUFFERED_METHODS", "ENGINES",
           "default_options", "check_options", "check_online_options", "options_of", "to_c", "from_c", "ctypes_fields", "c_header",
           "fmu_parameters", "add_arguments", "add_shared_arguments", "options_from_arguments", "C_HEADER_NAME"]

#: The online methods (OnlineIdentifier, the C core, the estimator FMUs).
ONLINE_METHODS = ("robust", "paper")
#: The buffered methods (BufferedIdentifier): one per orthogonal basis.
BUFFERED_METHODS = BASES
#: Implementations of the online methods: the C core where it runs the model (auto), or one of them.
ENGINES = ("auto", "c", "python")
#: File name of the generated C header (in ``fmus/estimator``).
C_HEADER_NAME = "duffid_options.h"


@dataclass(frozen=True)
class Option:
    """One option of the online estimator.

    Parameters
    ----------
    name : str
        Keyword of :class:`~duffid.identification.engine.OnlineIdentifier` and field of
        the C ``duffid_config``.
    methods : tuple of str
        The methods that take it.
    kind : {"real", "count", "choice", "bool", "prior"}
        ``real``: a finite number >= ``minimum``; ``count``: an integer >= 1; ``choice``:
        one of ``choices`` (C: its index); ``bool``; ``prior``: a mapping of parameter
        names to sizes (Python only; C has ``nominal[]``).
    default : object
        The Python default.
    description : str
        What it means (FMU variable description and CLI help).
    unit : str, optional
        Unit of a real option.
    choices : tuple of str
        The values of a choice option.
    unset : object
        The Python value (``"auto"`` or None) the C core codes as 0, if any.
    minimum : float
        Smallest valid value of a real option (a set value must exceed it when
        ``unset`` is given: 0 is then the unset code).
    fmu : bool
        A parameter of the estimator FMUs.
    default_text : str
        What the default means, where its value does not say it (CLI help).
    above : bool
        A real option must exceed ``minimum`` (not only reach it).
    alias : str
        Another command-line flag of the option (an older name kept for compatibility).
    """

    name: str
    methods: tuple[str, ...]
    kind: str
    default: Any
    description: str
    unit: str | None = None
    choices: tuple[str, ...] = ()
    unset: Any = "<none>"
    minimum: float = 0.0
    fmu: bool = True
    default_text: str = ""
    above: bool = False
    alias: str = ""

    @property
    def has_unset(self) -> bool:
        """Whether a Python value (``"auto"``, None) stands for C's 0."""
        return self.unset != "<none>"

    @property
    def c_kind(self) -> str:
        """``REAL`` (a C double) or ``CODE`` (a C int)."""
        return "REAL" if self.kind == "real" else "CODE"

    @property
    def c_default(self) -> float | int:
        """The default as the C core codes it."""
        return to_c(self, self.default)

    @property
    def c_maximum(self) -> int:
        """Largest C code of a coded option (-1: none)."""
        if self.kind == "choice":
            return len(self.choices) - 1
        if self.kind == "bool":
            return 1
        return -1

    @property
    def coded_description(self) -> str:
        """The description with the C coding (FMU variables): ``"..., 0 = auto"``."""
        if self.kind == "choice":
            return f"{self.description}: " + ", ".join(f"{i} {v}" for i, v in enumerate(self.choices))
        if self.has_unset:
            return f"{self.description}, 0 = {'default' if self.kind == 'count' else self.unset or 'none'}"
        return self.description

    def valid_values(self, c: bool = False) -> str:
        """The valid values in words, as Python (or, ``c=True``, the C core) takes them."""
        unit = f" ({self.unit})" if self.unit else ""
        if self.kind == "choice":
            return " or ".join(f"{i} ({v})" if c else repr(v) for i, v in enumerate(self.choices))
        if self.kind == "bool":
            return "0 or 1" if c else "True or False"
        if self.kind == "count":
            return ("0 (default) or " if c else "None (default) or ") + "an integer >= 1"
        if self.has_unset:
            head = f"0 ({self.unset or 'none'})" if c else repr(self.unset)
            return f"{head} or a positive number" + (" of seconds" if self.unit == "s" else unit)
        return f"a finite number {'>' if self.above else '>='} {_number(self.minimum)}{unit}"


def _number(value: float) -> str:
    return f"{value:g}"


_BOTH = ONLINE_METHODS
#: Every option, in FMU value-reference order (the FMU's ``method`` parameter comes first).
OPTIONS: tuple[Option, ...] = (
    Option("window", ("robust",), "real", "auto", "robust: window length", unit="s", unset="auto",
           default_text="auto: window_periods natural periods"),
    Option("window_periods", ("robust",), "real", 1.5, "robust: auto window in natural periods"),
    Option("max_window", ("robust",), "real", 1.0, "robust: longest window (buffer capacity)", unit="s"),
    Option("forgetting", ("robust",), "real", None, "robust: forgetting time constant", unit="s",
           unset=None, default_text="none"),
    Option("rows", ("robust",), "choice", "integrals", "robust: row kernels",
           choices=("integrals", "bernstein", "paper")),
    Option("n_rows", ("robust",), "count", None, "robust: rows per window", unset=None,
           default_text="max(unknowns + 1, 8)"),
    Option("max_condition", _BOTH, "real", 1e6, "largest condition number of an identified solution"),
    Option("max_uncertainty", ("robust",), "real", 0.01,
           "robust: largest relative standard error of an identified parameter"),
    Option("min_time", _BOTH, "real", 0.01, "shortest window of an identified solution", unit="s"),
    Option("settle", ("robust",), "real", 0.01, "robust: time an estimate must stay trustworthy", unit="s"),
    Option("gamma", ("paper",), "real", 20.0, "paper: filter gain"),
    Option("quadrature", ("paper",), "choice", "adams3", "paper: quadrature of the integrators",
           choices=("adams3", "trapezoid")),
    Option("sign_in_numerator", ("paper",), "bool", False,
           "paper: the sign convention of the numerator (sign_in_numerator)"),
    Option("deadband", _BOTH, "real", 0.0,
           "|dx| <= deadband (displacement units) keeps the previous sign of velocity", fmu=False),
    Option("jump_restart", ("robust",), "bool", False,
           "robust: a force that jumps between two samples restarts the window (engine.JUMP_FACTOR)", fmu=False),
    Option("nominal", ("robust",), "prior", None,
           "optional prior sizes {parameter: size}: the trust test's scale (None: from the data)", fmu=False),
    Option("change_threshold", ("robust",), "real", 4.0,
           "robust: departure of the recent estimate, in combined standard errors, that marks a change",
           unset=None, default_text="4; none: no change test"),
    Option("change_memory", ("robust",), "real", "auto", "robust: memory of the change test's recent estimate",
           unit="s", unset="auto", default_text="auto: 2 windows"),
)
_BY_NAME = {o.name: o for o in OPTIONS}

_BUF = BUFFERED_METHODS
#: Every option of the buffered methods (Python only: no C coding, no FMU parameter).
BUFFERED_OPTIONS: tuple[Option, ...] = (
    Option("window", _BUF, "real", 0.25, "buffered: window length", unit="s", above=True, fmu=False,
           default_text="0.25, a natural period of the paper's plant"),
    Option("n_terms", _BUF, "count", None, "buffered: basis functions per window", unset=None, fmu=False,
           default_text="24 for legendre and chebyshev, 128 for block-pulse and haar, at most the window's "
                        "samples", alias="terms"),
    Option("every", _BUF, "count", None, "buffered: samples between re-identifications", unset=None, fmu=False,
           default_text="the window's samples: back-to-back windows"),
    Option("quadrature", _BUF, "choice", "gauss", "buffered: quadrature of the coefficient integrals",
           choices=QUADRATURES, fmu=False),
    Option("form", _BUF, "choice", "per-dof", "buffered: per-DOF equations or the matrix form (eqs. 36-37)",
           choices=("per-dof", "matrix"), fmu=False),
    Option("repeated", _BUF, "choice", "power", "buffered: repeated integration: powers of P (the paper's) "
           "or the exact matrices", choices=("power", "exact"), fmu=False),
    Option("accumulate", _BUF, "bool", False, "buffered: least squares over all windows so far", fmu=False),
    Option("max_condition", _BUF, "real", 1e8, "buffered: largest scaled condition number of an identified window",
           fmu=False),
    Option("max_uncertainty", _BUF, "real", 0.05,
           "buffered: largest relative standard error of an identified window's unknowns", fmu=False),
    Option("deadband", _BUF, "real", 0.0,
           "|dx| <= deadband (displacement units) keeps the previous sign of velocity", fmu=False),
)


def options_of(method: str) -> list[Option]:
    """The options of ``method`` (online or buffered), in schema order."""
    if method in ONLINE_METHODS:
        return [o for o in OPTIONS if method in o.methods]
    if method in BUFFERED_METHODS:
        return [o for o in BUFFERED_OPTIONS if method in o.methods]
    raise InputError(f"unknown method {method!r}; choose one of {', '.join(ONLINE_METHODS + BUFFERED_METHODS)}")


_of = options_of


def default_options(method: str) -> dict[str, Any]:
    """A copy of the default options of ``method`` (online or buffered)."""
    return check_options(method, {})


def _check_value(option: Option, value: Any) -> Any:
    def bad() -> InputError:
        return InputError(f"option {option.name} must be {option.valid_values()}, got {value!r}")

    if option.has_unset and (value is option.unset or value == option.unset):
        return option.unset
    if option.kind == "real":
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
            raise bad()
        if value < option.minimum or ((option.has_unset or option.above) and value <= option.minimum):
            raise bad()
        return value
    if option.kind == "count":
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
            raise bad()
        return int(value)
    if option.kind == "choice":
        if value not in option.choices:
            raise bad()
        return value
    if option.kind == "bool":
        if not isinstance(value, (bool, numbers.Integral)) or value not in (0, 1):
            raise bad()
        return bool(value)
    # prior
    if value is not None and not (isinstance(value, Mapping) and all(
            isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v) for v in value.values())):
        raise InputError(f"option {option.name} must be None or a mapping of parameter names to finite "
                         f"sizes, got {value!r}")
    return value


def check_options(method: str, options: Mapping[str, Any]) -> dict[str, Any]:
    """Validate ``options`` of ``method`` and merge them with its defaults.

    Parameters
    ----------
    method : str
        An online method (:data:`ONLINE_METHODS`) or a buffered one (:data:`BUFFERED_METHODS`).
    options : mapping
        Option values by name (:data:`OPTIONS`).

    Returns
    -------
    dict
        Every option of the method, the given values checked, the others at their defaults.

    Raises
    ------
    InputError
        Unknown method, or an option value out of range (the message names it and its range).
    OptionError
        An option the method does not have (the message lists those it has).
    """
    mine = {o.name: o for o in options_of(method)}
    unknown = set(options) - set(mine)
    if unknown:
        raise OptionError(f"method {method!r} has no option(s) {sorted(unknown)}; its options are {sorted(mine)}")
    return {name: _check_value(o, options[name]) if name in options else o.default for name, o in mine.items()}


def check_online_options(method: str, options: Mapping[str, Any]) -> dict[str, Any]:
    """:func:`check_options` for the online identifiers (OnlineIdentifier, the C core), which
    refuse the buffered methods by name."""
    if method not in ONLINE_METHODS:
        raise InputError(f"unknown online method {method!r}; choose one of {', '.join(ONLINE_METHODS)} "
                         "(the buffered bases run through identify() or "
                         "duffid.identification.buffered.BufferedIdentifier)")
    return check_options(method, options)


def to_c(option: Option | str, value: Any) -> float | int:
    """``value`` of an option as the C core codes it (``"auto"``/None -> 0, a choice -> its index)."""
    option = _BY_NAME[option] if isinstance(option, str) else option
    if option.has_unset and (value is option.unset or value == option.unset):
        return 0 if option.kind != "real" else 0.0
    if option.kind == "choice":
        return option.choices.index(value)
    if option.kind in ("bool", "count"):
        return int(value)
    return float(value)


def from_c(option: Option | str, code: float) -> Any:
    """The Python value of an option from its C code (the inverse of :func:`to_c`).

    Raises
    ------
    InputError
        If ``code`` is not a valid code of the option (the message names it and its range).
    """
    option = _BY_NAME[option] if isinstance(option, str) else option
    code = float(code)
    if option.has_unset and code == 0.0:
        return option.unset
    if option.kind == "real":
        return _check_value(option, code)
    if not code.is_integer() or code < 0 or (option.c_maximum >= 0 and code > option.c_maximum):
        raise InputError(f"parameter {option.name} must be {option.valid_values(c=True)}, got {code:g}")
    if option.kind == "choice":
        return option.choices[int(code)]
    if option.kind == "bool":
        return bool(code)
    return int(code)


def c_options() -> list[Option]:
    """The options the C core has (the online methods', every kind but ``prior``), FMU parameters first."""
    core = [o for o in OPTIONS if o.kind != "prior"]
    return [o for o in core if o.fmu] + [o for o in core if not o.fmu]


def ctypes_fields(real: Any = ctypes.c_double) -> list[tuple[str, Any]]:
    """The ctypes fields of the options in ``duffid_config`` (after its fixed head); ``real`` is
    the core's real type (``ctypes.c_float`` for a core built with ``-DDUFFID_REAL=float``)."""
    return [(o.name, real if o.c_kind == "REAL" else ctypes.c_int) for o in c_options()]


def _c_literal(value: float | int, kind: str) -> str:
    return repr(float(value)) if kind == "REAL" else str(int(value))


def _methods_mask(option: Option) -> str:
    return " | ".join(f"DUFFID_FOR_{m.upper()}" for m in option.methods)


def c_header() -> str:
    """The text of ``fmus/estimator/duffid_options.h``, generated from :data:`OPTIONS`."""
    lines = [
        "/* The options of the estimator core: GENERATED by duffid.identification.options from its",
        " * OPTIONS schema (the single source of every option); do not edit. `make generated`",
        " * rewrites it; tests/test_options.py checks it is current.",
        " *",
        " * X(kind, name, default, minimum, maximum, methods, valid values)",
        " *   kind     REAL (a duffid_real >= minimum; 0 means unset where the valid values say so)",
        " *            or CODE (an int in 0 .. maximum; maximum -1: any int >= 0)",
        " *   methods  DUFFID_FOR_ROBUST | DUFFID_FOR_PAPER: the methods that read it",
        " */",
        "#ifndef DUFFID_OPTIONS_H",
        "#define DUFFID_OPTIONS_H",
        "",
        "#define DUFFID_FOR_ROBUST 1",
        "#define DUFFID_FOR_PAPER 2",
        "#define DUFFID_CTYPE_REAL duffid_real /* duffid_model.h: double, or float with -DDUFFID_REAL=float */",
        "#define DUFFID_CTYPE_CODE int",
        "",
    ]

    def table(macro: str, options: list[Option], comment: str) -> None:
        lines.append(f"/* {comment}")
        for o in options:
            unit = f" [{o.unit}]" if o.unit else ""
            lines.append(f" *   {o.name}{unit}: {o.coded_description}")
        lines.append(" */")
        lines.append(f"#define {macro}(X) \\")
        for i, o in enumerate(options):
            minimum = _c_literal(o.minimum, "REAL")
            end = " \\" if i < len(options) - 1 else ""
            lines.append(f"    X({o.c_kind}, {o.name}, {_c_literal(o.c_default, o.c_kind)}, {minimum}, "
                         f"{o.c_maximum}, {_methods_mask(o)}, \"{o.valid_values(c=True)}\"){end}")
        lines.append("")

    table("DUFFID_FMU_OPTIONS", [o for o in c_options() if o.fmu],
          "Options that are estimator FMU parameters, in value-reference order (after `method`).")
    table("DUFFID_OTHER_OPTIONS", [o for o in c_options() if not o.fmu],
          "Options of the core that are not FMU parameters.")
    lines += ["#define DUFFID_OPTIONS(X) DUFFID_FMU_OPTIONS(X) DUFFID_OTHER_OPTIONS(X)", "",
              "#endif /* DUFFID_OPTIONS_H */", ""]
    return "\n".join(lines)


def fmu_parameters() -> list[Option]:
    """The options that are parameters of the estimator FMUs, in value-reference order."""
    return [o for o in OPTIONS if o.fmu]


# ---------------------------------------------------------------------- command line
def _flag(option: Option) -> str:
    return "--" + option.name.replace("_", "-")


def _find(method: str, name: str) -> Option:
    for o in options_of(method):
        if o.name == name:
            return o
    raise InputError(f"option {name} is not an option of the {method} method")


def _shown(o: Option) -> str:
    unit = f" [{o.unit}]" if o.unit else ""
    return f"{o.description}{unit} (default {o.default_text or o.default})"


def add_arguments(parser: argparse.ArgumentParser | Any, method: str, names: tuple[str, ...],
                  defaults_from: str | None = None) -> None:
    """Add the flags of ``names`` (options of ``method``) to ``parser`` (or an argument group).

    Each flag's help text is the option's description with its default; its type checks
    the option's range (``--window auto`` for the unset value of ``window``).
    """
    for name in names:
        _add_flag(parser, [_find(method, name)])


def add_shared_arguments(parser: argparse.ArgumentParser | Any, names: tuple[str, ...],
                         methods: tuple[str, ...]) -> None:
    """One flag per name for every variant of that option among ``methods`` (e.g. ``--window``
    of the robust and the buffered methods): its help states each variant's meaning and
    default, its type accepts what any variant accepts; the method's own check applies when the
    options are built (:func:`options_from_arguments`, :func:`check_options`)."""
    for name in names:
        variants: list[Option] = []
        for method in methods:
            o = next((o for o in options_of(method) if o.name == name), None)
            if o is not None and o not in variants:
                variants.append(o)
        if not variants:
            raise InputError(f"option {name} is not an option of the methods {', '.join(methods)}")
        _add_flag(parser, variants)


def _add_flag(parser: Any, variants: list[Option]) -> None:
    o = variants[0]
    names = [_flag(o)] + ([f"--{o.alias.replace('_', '-')}"] if o.alias else [])
    shown = "; ".join(dict.fromkeys(_shown(v) for v in variants))
    kinds = {v.kind for v in variants}
    if kinds == {"bool"}:
        parser.add_argument(*names, dest=o.name, action=argparse.BooleanOptionalAction, default=None, help=shown)
    elif kinds == {"choice"}:
        choices = tuple(dict.fromkeys(c for v in variants for c in v.choices))
        parser.add_argument(*names, dest=o.name, choices=choices, default=None, help=shown)
    else:
        parser.add_argument(*names, dest=o.name, type=_parser_of(variants), default=None,
                            metavar=o.name.upper(), help=shown)


#: How a flag names the value None of an option whose unset value is None (``--forgetting none``).
_NONE = "none"


def _parser_of(variants: Option | list[Option]):
    variants = [variants] if isinstance(variants, Option) else variants

    def parse(text: str) -> Any:
        errors = []
        for option in variants:
            if option.has_unset and option.unset is not None and text == option.unset:
                return option.unset
            if option.has_unset and option.unset is None and text == _NONE:
                return _NONE  # None itself would read as "not given"
            try:
                value: Any = int(text) if option.kind == "count" else float(text)
                return _check_value(option, value)
            except (ValueError, InputError):
                errors.append(option.valid_values())
        raise argparse.ArgumentTypeError(f"{text!r} is not {' or '.join(dict.fromkeys(errors))}")
    parse.__name__ = variants[0].name
    return parse


def options_from_arguments(args: argparse.Namespace, method: str) -> dict[str, Any]:
    """The options of ``method`` given as flags (those left unset are not included), each
    checked against the method's own variant of the option.

    Raises
    ------
    InputError
        A value the method does not take (a shared flag such as ``--window auto`` given to a
        buffered method): the message names the flag, the value and what the method takes.
    """
    out = {}
    for o in options_of(method):
        value = getattr(args, o.name, None)
        if value == _NONE and o.has_unset and o.unset is None:
            out[o.name] = None
        elif value is not None:
            try:
                out[o.name] = _check_value(o, value)
            except InputError:
                raise InputError(f"{_flag(o)} {value}: the {method} method takes {o.valid_values()}") from None
    return out
