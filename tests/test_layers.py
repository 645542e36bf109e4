"""The package's layers: the library (``kite_env``) never imports the top-level ``agents`` package (its recipes and
shipped models are data, found by path), and ``agents.baseline`` / ``agents.policies`` hand on the library's own
policies to users' imports; the analyses (``kite_env.analysis``) are imported by nothing else of the library; the wing
(``kite_env.fsi.AeroelasticWing``) is used through its public interface; ``kite_env.compiled`` alone imports numba."""

from __future__ import annotations

import ast
from pathlib import Path

LIBRARY = Path(__file__).resolve().parents[1] / "kite_env"


def _imported_modules(path: Path) -> set[str]:
    """Every module an ``import`` statement of ``path`` names, at any depth (function-local imports too); ``from m
    import a`` names ``m`` and ``m.a`` (``a`` may be a submodule), a relative import is resolved against the package
    of ``path`` (a file of ``kite_env``)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                package = path.relative_to(LIBRARY.parent).parent.parts
                base = list(package[:len(package) - (node.level - 1)])
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            names.add(module)
            names.update(f"{module}.{a.name}" for a in node.names)
    return names


def test_the_library_never_imports_the_agents_package():
    offenders = {str(p.relative_to(LIBRARY.parent)): sorted(m for m in _imported_modules(p)
                                                            if m == "agents" or m.startswith("agents."))
                 for p in sorted(LIBRARY.rglob("*.py"))}
    assert {p: m for p, m in offenders.items() if m} == {}


def test_only_the_analyses_import_the_analysis_package():
    """kite_env.analysis holds analyses of the model (turn-rate linearisations, steering stiffness, the L/D split):
    they build on the library, nothing of the library (the env, the dynamics, the wing, the CLIs) builds on them."""
    analysis = LIBRARY / "analysis"
    assert (analysis / "__init__.py").is_file()
    offenders = {str(p.relative_to(LIBRARY.parent)): sorted(m for m in _imported_modules(p)
                                                            if m == "kite_env.analysis"
                                                            or m.startswith("kite_env.analysis."))
                 for p in sorted(LIBRARY.rglob("*.py")) if analysis not in p.parents}
    assert {p: m for p, m in offenders.items() if m} == {}


def test_only_the_compiled_module_imports_numba():
    """kite_env.compiled is the one place that imports numba (``njit`` with its fallback, the backend choice, the
    shared options); every compiled kernel takes them from there."""
    importers = sorted(str(p.relative_to(LIBRARY.parent)) for p in LIBRARY.rglob("*.py")
                       if any(m == "numba" or m.startswith("numba.") for m in _imported_modules(p)))
    assert importers == ["kite_env/compiled.py"]


def test_agents_modules_re_export_the_library_policies():
    import agents.baseline
    import agents.policies
    import kite_env.policies
    import kite_env.policies.baseline

    assert agents.baseline.BaselineAgent is kite_env.policies.baseline.BaselineAgent
    assert agents.baseline.BaselinePolicy is kite_env.policies.baseline.BaselinePolicy
    for name in agents.policies.__all__:
        assert getattr(agents.policies, name) is getattr(kite_env.policies, name), name
    assert kite_env.policies.MODELS_DIR.parent.name == "agents" and kite_env.policies.MODELS_DIR.name == "models"


#: names that hold an AeroelasticWing outside kite_env/fsi.py (``wing``, ``self.wing``, ``dyn.wing``, ``self._wing``)
_WING_NAMES = {"wing", "_wing"}
#: calls that build one (a name assigned from them is a wing too, e.g. ``ref = AeroelasticWing(mesh, cfg)``)
_WING_BUILDERS = {"AeroelasticWing", "nominal_wing"}


def _name_of(node: ast.AST) -> str | None:
    """``wing`` for ``wing``, ``self.wing``, ``dyn.wing``; the called name for a call; None otherwise."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        return node.attr
    if isinstance(node, ast.Call):
        return _name_of(node.func)
    return None


def _private_wing_accesses(source: str, name: str) -> list[str]:
    """``name:line: expr`` of every attribute access ``<wing>._member`` (a single leading underscore, not a dunder)
    in the module ``source``, ``<wing>`` a name of :data:`_WING_NAMES` or one assigned from a wing or a builder of
    one, in the order of the source."""
    tree = ast.parse(source, name)
    wings = set(_WING_NAMES)
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign):
            src = _name_of(node.value)
            if src in _WING_BUILDERS or src in _WING_NAMES:
                wings.update(t.id for t in node.targets if isinstance(t, ast.Name))
    hits = sorted((node.lineno, node.col_offset, ast.unparse(node)) for node in ast.walk(tree)
                  if isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")
                  and _name_of(node.value) in wings)
    return [f"{name}:{line}: {expr}" for line, _, expr in hits]


def test_the_scan_finds_private_accesses_of_a_wing():
    """The scan below sees the forms the dynamics used to take (a method, an attribute written, a name bound to a
    built wing), and not a public member or another object's private one."""
    src = ("wing._downwashed(X)\nself.wing._downwash = None\ndyn.wing._mono_solvers['prescribed'].asm\n"
           "ref = AeroelasticWing(mesh, cfg)\nref._solution()\nwing.solve(None, X)\nsim._flight_state(t, s)\n")
    assert _private_wing_accesses(src, "probe.py") == [
        "probe.py:1: wing._downwashed", "probe.py:2: self.wing._downwash", "probe.py:3: dyn.wing._mono_solvers",
        "probe.py:5: ref._solution"]


def test_no_module_but_fsi_reaches_into_a_wings_private_members():
    """The wing (kite_env.fsi.AeroelasticWing) is used through its public interface: the dynamics, the analyses and
    every other module call its public methods and properties (downwashed, update_downwash, rotate_downwash,
    aero_options, update_tube_stiffness, prescribed_assembly, load_vector, solution, continuation, ...), never a
    ``_private`` member, which only kite_env/fsi.py touches."""
    found = [hit for p in sorted(LIBRARY.rglob("*.py")) if p != LIBRARY / "fsi.py"
             for hit in _private_wing_accesses(p.read_text(), str(p.relative_to(LIBRARY.parent)))]
    assert not found, "private members of an AeroelasticWing used outside kite_env/fsi.py:\n" + "\n".join(found)
