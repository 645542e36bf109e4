"""The package's layers: the library (``kite_env``) never imports the top-level ``agents`` package (its recipes and
shipped models are data, found by path), and ``agents.baseline`` / ``agents.policies`` hand on the library's own
policies to users' imports."""

from __future__ import annotations

import ast
from pathlib import Path

LIBRARY = Path(__file__).resolve().parents[1] / "kite_env"


def _imported_modules(path: Path) -> set[str]:
    """Every module an ``import`` statement of ``path`` names, at any depth (function-local imports too)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
    return names


def test_the_library_never_imports_the_agents_package():
    offenders = {str(p.relative_to(LIBRARY.parent)): sorted(m for m in _imported_modules(p)
                                                            if m == "agents" or m.startswith("agents."))
                 for p in sorted(LIBRARY.rglob("*.py"))}
    assert {p: m for p, m in offenders.items() if m} == {}


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
