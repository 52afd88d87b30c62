"""The package's architecture, checked: imports point down the layers, no cycles, no private
names across modules, no heavy dependency where it is not needed, and a documented public API
(python-control's meta-test style)."""
from __future__ import annotations

import ast
import graphlib
import importlib
import inspect
import re
import subprocess
import sys
from pathlib import Path

import pytest

import duffid

PACKAGE = Path(duffid.__file__).resolve().parent

#: Layers, bottom up: a module may import from its own layer's package and from lower layers.
#: Packages on one layer are independent of each other.
LAYERS = (
    ("errors",),
    ("assets", "cbuild"),
    ("data",),
    ("models",),
    ("identification",),
    ("analysis", "fmu"),
    ("modelica",),
    ("cosim",),
    ("control",),
    ("campaign",),
    ("apps",),
    ("cli",),
)
_LEVEL = {name: i for i, names in enumerate(LAYERS) for name in names}


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = ["duffid", *path.relative_to(PACKAGE).with_suffix("").parts]
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _is_type_checking(node: ast.If) -> bool:
    return isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING"


def _imports(module: str, path: Path, type_checking: bool = False) -> list[tuple[str, list[str], int]]:
    """(imported module, names, line) of every import of duffid in ``path``, deferred ones
    included, annotations-only (``if TYPE_CHECKING:``) ones only with ``type_checking``."""
    tree = ast.parse(path.read_text())
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node) and not type_checking:
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if target == "duffid" or target.startswith("duffid."):
                names = [a.name for a in node.names]
                submodules = [f"{target}.{n}" for n in names if f"{target}.{n}" in MODULES]
                if submodules:
                    found.extend((s, [], node.lineno) for s in submodules)
                else:
                    found.append((target, names, node.lineno))
        elif isinstance(node, ast.Import):
            found.extend((a.name, [], node.lineno) for a in node.names if a.name.startswith("duffid"))
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def test_every_subpackage_is_on_a_layer():
    assert {_layer(m) for m in MODULES} - {None, "__main__"} == set(_LEVEL)


def test_imports_only_point_down_the_layers():
    wrong = []
    for module, path in MODULES.items():
        mine = _layer(module)
        if mine in (None, "__main__"):
            continue
        for target, _, line in _imports(module, path):
            theirs = _layer(target)
            if theirs is None or theirs == mine:
                continue
            if _LEVEL[theirs] >= _LEVEL[mine]:
                wrong.append(f"{path.relative_to(PACKAGE)}:{line}: {module} ({mine}) imports {target} ({theirs})")
    assert not wrong, "imports pointing up or across the layers:\n" + "\n".join(wrong)


def test_no_import_cycles():
    """Not even through annotations-only imports (a module that needs another's type only for
    its annotations takes a Protocol of a lower module instead)."""
    graph = {m: set() for m in MODULES}
    for module, path in MODULES.items():
        for target, _, _ in _imports(module, path, type_checking=True):
            while target not in MODULES:  # "duffid.x.y" where y is a name
                target = target.rpartition(".")[0]
            if target != module and not (module == "duffid" or target == "duffid"):
                graph[module].add(target)
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as exc:
        pytest.fail(f"import cycle: {' -> '.join(exc.args[1])}")


def test_no_private_name_is_imported_from_another_module():
    wrong = []
    for module, path in MODULES.items():
        for target, names, line in _imports(module, path):
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private:
                wrong.append(f"{path.relative_to(PACKAGE)}:{line}: {', '.join(private)} from {target}")
    assert not wrong, "private names imported across modules:\n" + "\n".join(wrong)


def _private_attributes(tree: ast.AST) -> set[str]:
    """The underscore names a module defines: functions, classes, module names, attributes it
    assigns."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
    return {n for n in names if n.startswith("_") and not n.startswith("__")}


def _third_party_names(tree: ast.AST) -> set[str]:
    """Names bound by imports of other packages (their underscore attributes are their business)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update((a.asname or a.name).split(".")[0] for a in node.names if not a.name.startswith("duffid"))
        elif isinstance(node, ast.ImportFrom) and not node.level and not (node.module or "").startswith("duffid"):
            names.update(a.asname or a.name for a in node.names)
    return names


def test_no_module_reads_another_modules_underscore_attributes():
    """``obj._x`` where ``_x`` is defined by another duffid module (not this one): a private
    member read across modules (python's convention; a public view belongs in the owner)."""
    trees = {path: ast.parse(path.read_text()) for path in MODULES.values()}
    defined = {path: _private_attributes(tree) for path, tree in trees.items()}
    wrong = []
    for path, tree in trees.items():
        foreign = _third_party_names(tree)
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")):
                continue
            base = node.value
            while isinstance(base, ast.Attribute):
                base = base.value
            if isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"):
                continue
            if isinstance(base, ast.Name) and base.id in foreign:
                continue
            if node.attr not in defined[path] and any(node.attr in d for p, d in defined.items() if p != path):
                wrong.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: {ast.unparse(node)}")
    assert not wrong, "underscore attributes of other modules read:\n" + "\n".join(sorted(wrong))


@pytest.mark.parametrize("module, heavy", [
    ("duffid", "pymoca"),
    ("duffid.fmu.estimator", "pymoca"),
    ("duffid.control.controller_fmu", "pymoca"),
    ("duffid.cosim.system", "pymoca"),
    ("duffid", "matplotlib"),
])
def test_a_module_does_not_load_what_it_does_not_need(module, heavy):
    code = f"import sys, {module}; print({heavy!r} in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False", f"importing {module} loads {heavy}"


def test_importing_duffid_leaves_the_matplotlib_backend_alone():
    code = ("import matplotlib; before = matplotlib.get_backend(); import duffid.apps.plots, "
            "duffid.analysis.silverbox; print(before == matplotlib.get_backend())")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "True"


# ---------------------------------------------------------------------- public API
def _public_callables():
    for module in sorted(MODULES):
        if module.endswith("__main__"):
            continue
        mod = importlib.import_module(module)
        for name in getattr(mod, "__all__", ()):
            obj = getattr(mod, name)
            if (inspect.isfunction(obj) or inspect.isclass(obj)) and obj.__module__ == module:
                yield f"{module}.{name}", obj


PUBLIC = dict(_public_callables())


def _documented_parameters(doc: str) -> list[str]:
    """Names in the numpydoc ``Parameters`` section of ``doc``."""
    match = re.search(r"^\s*Parameters\n\s*-{3,}\n(.*?)(?:\n\s*\n\s*[A-Z][a-z]+( [A-Za-z]+)?\n\s*-{3,}|\Z)",
                      doc, flags=re.S | re.M)
    if not match:
        return []
    indent = min((len(line) - len(line.lstrip()) for line in match.group(1).splitlines() if line.strip()),
                 default=0)
    names = []
    for line in match.group(1).splitlines():
        if line.strip() and len(line) - len(line.lstrip()) == indent:
            head = line.strip().split(" : ")[0]
            if not re.fullmatch(r"\*{0,2}\w+(\s*,\s*\*{0,2}\w+)*", head):
                break  # prose after the entries
            names += [n.strip().lstrip("*") for n in head.split(",")]
    return names


def test_the_curated_api_is_short_and_documented():
    assert len(duffid.__all__) <= 30
    for name in duffid.__all__:
        obj = getattr(duffid, name)
        if callable(obj):
            assert inspect.getdoc(obj), f"duffid.{name} has no docstring"


@pytest.mark.parametrize("name", sorted(PUBLIC))
def test_every_public_function_and_class_is_documented(name):
    obj = PUBLIC[name]
    doc = inspect.getdoc(obj)
    assert doc and len(doc.split()) >= 3, f"{name} has no docstring"


@pytest.mark.parametrize("name", sorted(PUBLIC))
def test_documented_parameters_exist(name):
    obj = PUBLIC[name]
    target = obj.__init__ if inspect.isclass(obj) else obj
    doc = inspect.getdoc(obj) or ""
    if inspect.isclass(obj) and "Parameters" not in doc:
        doc = inspect.getdoc(obj.__init__) or ""
    try:
        signature = inspect.signature(target)
    except (TypeError, ValueError):
        return
    accepted = set(signature.parameters)
    if inspect.isclass(obj) and obj.__init__ is object.__init__:
        return
    documented = _documented_parameters(doc)
    unknown = [n for n in documented if n not in accepted and n not in ("options", "kwargs", "args")
               and not n.startswith("<")]
    assert not unknown, f"{name} documents parameters it does not have: {unknown}"


def test_unknown_keyword_arguments_are_rejected(case_a):
    """Functions taking ``**options`` say which option they do not have (no silent ignore)."""
    from duffid.errors import OptionError
    from duffid.identification.batch import estimate
    from duffid.identification.equation import identify_equation

    calls = {
        "identify": lambda: duffid.identify(case_a, duffid.Duffing1(), gama=1.0),
        "estimate (online)": lambda: estimate(case_a, duffid.Duffing1(), "robust", windw=0.2),
        "estimate (buffered)": lambda: estimate(case_a, duffid.Duffing1(), "legendre", n_term=8),
        "OnlineIdentifier": lambda: duffid.OnlineIdentifier(duffid.Duffing1(), case_a.dt, "paper", gama=1.0),
        "identify_equation": lambda: identify_equation(case_a, "m*der(x,2) + k*x = f", gama=1.0),
    }
    for label, call in calls.items():
        with pytest.raises(OptionError, match="no option") as info:
            call()
        assert isinstance(info.value, TypeError), label


def test_errors_share_one_base():
    from duffid import errors

    for name in errors.__all__:
        cls = getattr(errors, name)
        assert issubclass(cls, errors.DuffidError), name
        assert cls is errors.DuffidError or issubclass(cls, (ValueError, TypeError, RuntimeError, OSError, ImportError)), name


def test_the_readme_layout_names_every_module():
    readme = (PACKAGE.parents[1] / "docs" / "layout.md").read_text()  # the Layout moved from README.md
    layout = readme.split("## Layout", 1)[1].split("\n## ", 1)[0]
    missing = []
    for module, path in MODULES.items():
        relative = path.relative_to(PACKAGE)
        if relative.name in ("__init__.py", "__main__.py"):
            name = f"{relative.parent.as_posix()}/" if relative.parent.parts else None
        else:
            name = relative.name
        if name and name not in layout:
            missing.append(str(relative))
    assert not missing, f"README's Layout does not name {missing}"


def test_every_identifier_implements_one_interface_with_the_same_input_checks():
    from duffid.errors import InputError
    from duffid.identification.buffered import BufferedIdentifier
    from duffid.identification.c_core import CIdentifier
    from duffid.identification.identifier import Identifier

    makers = {"OnlineIdentifier": lambda dt: duffid.OnlineIdentifier(duffid.Duffing1(), dt),
              "CIdentifier": lambda dt: CIdentifier(duffid.Duffing1(), dt),
              "BufferedIdentifier": lambda dt: BufferedIdentifier(duffid.Duffing1(), dt, "legendre", window=0.1)}
    for label, make in makers.items():
        for bad in (0.0, -1e-3, float("nan"), float("inf"), True):
            with pytest.raises(InputError, match="dt must be a positive number of seconds"):
                make(bad)
        ident = make(1e-3)
        assert isinstance(ident, Identifier), label
        assert ident.parameter_names == ("m", "b", "k", "kp"), label
        with pytest.raises(InputError, match=r"duffing1: update needs 1 displacement\(s\) and 1 force\(s\)"):
            ident.update([0.0, 0.0], 1.0)


def test_without_the_optional_modelica_dependency_duffid_works_and_says_what_to_install(tmp_path):
    code = ("import sys; sys.modules['pymoca'] = None\n"
            "import duffid, duffid.fmu.estimator, duffid.cosim.system, duffid.control.closed_loop\n"
            "from duffid.cli import main\n"
            f"sys.exit(main(['build-fmus', '--out', {str(tmp_path)!r}]))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 2, done.stderr
    assert "duffid build-fmus: error: the Modelica export needs pymoca" in done.stderr
    assert "pip install 'duffid[modelica]'" in done.stderr and "Traceback" not in done.stderr
