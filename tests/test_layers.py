"""The package's layers: no module imports from a layer above its own.

Every module under ``companion/`` is parsed with :mod:`ast` (nothing is imported)
and each import is checked against :data:`MAY_IMPORT`: imports at any depth count
(function-level imports, ``if TYPE_CHECKING:`` blocks), as do ``from companion import
x``, relative imports and ``importlib.import_module("companion.x")`` with a literal
name. A module's layer is the first name under ``companion`` (``companion/nav/blend.py``
is in ``nav``; ``companion/__init__.py`` is the package root, ``""``).

The rule, lowest first (docs/architecture.md):

    types, ranges  <  nav  <  integrity  <  engine
    raw (raw-observation positioning): types, ranges and nav
    mavlink: types, ranges and nav only (never the engine or integrity)
    ubx (the raw receiver's edge): types, ranges, nav and raw
    everything else (pipeline, service, replay, cli, ...): above all of these

and the pure core (root, types, ranges, nav, raw, integrity, engine) imports no I/O,
clock, MAVLink or UBX library (:data:`CORE_MAY_NOT_IMPORT`).
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "companion"
PACKAGE = "companion"

BASE = frozenset({"", "types", "ranges"})
"""The bottom layer: the package root, the typed samples and outputs, the range helper."""

MAY_IMPORT: dict[str, frozenset[str]] = {
    "": BASE,
    "types": BASE,
    "ranges": BASE,
    "nav": BASE | {"nav"},
    "integrity": BASE | {"nav", "integrity"},
    "engine": BASE | {"nav", "integrity", "engine"},
    "mavlink": BASE | {"nav", "mavlink"},
    "raw": BASE | {"nav", "raw"},
    "ubx": BASE | {"nav", "raw", "ubx"},
}
"""Layer -> the layers its modules may import. The rule table: keep it small."""

APPLICATION = frozenset(
    {
        "__main__",
        "batch",
        "cli",
        "config",
        "console",
        "deploy",
        "evaluate",
        "inspection",
        "inspection_plot",
        "notify",
        "params",
        "params_table",
        "pipeline",
        "presets",
        "recorder",
        "replay",
        "service",
        "sim",
    }
)
"""Layers above every layer of :data:`MAY_IMPORT`: they may import any of them (and each
other). A new top-level module or package must be put in one of the two tables."""

CORE = ("", "types", "ranges", "nav", "raw", "integrity", "engine")
"""The pure core: no I/O, no clock, no MAVLink."""

CORE_MAY_NOT_IMPORT = frozenset(
    {"asyncio", "matplotlib", "pymavlink", "pyubx2", "serial", "signal", "socket", "time"}
)
"""Top-level libraries the core never imports (time comes from the samples' ``t_s``)."""


# --------------------------------------------------------------------------- the walker


def module_name(path: Path, package_dir: Path = PACKAGE_DIR) -> tuple[str, bool]:
    """Dotted module name of a file under ``package_dir`` and whether it is a package."""
    rel = path.relative_to(package_dir.parent).with_suffix("")
    parts = list(rel.parts)
    is_package = parts[-1] == "__init__"
    if is_package:
        parts.pop()
    return ".".join(parts), is_package


def layer_of(module: str) -> str | None:
    """The layer of a dotted name inside the package ("" for the root), None outside it.

    ``companion.x`` is layer ``x`` when ``companion/x.py`` or ``companion/x/`` exists;
    otherwise ``x`` is a name defined in the package root (``__version__``): layer "".
    """
    parts = module.split(".")
    if parts[0] != PACKAGE:
        return None
    if len(parts) == 1:
        return ""
    name = parts[1]
    if (PACKAGE_DIR / f"{name}.py").is_file() or (PACKAGE_DIR / name).is_dir():
        return name
    return ""


def imports_of(source: str, module: str, is_package: bool) -> Iterator[tuple[int, str]]:
    """``(line, imported dotted name)`` of every import in ``source``, at any depth.

    ``from companion import x`` gives ``companion.x``; relative imports are resolved
    against ``module``; ``importlib.import_module`` / ``__import__`` with a literal
    absolute name count too. In the order of the source lines.
    """
    return iter(sorted(_imports(ast.parse(source), module, is_package), key=lambda x: x[0]))


def _imports(tree: ast.AST, module: str, is_package: bool) -> Iterator[tuple[int, str]]:
    package = module if is_package else module.rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")
                if node.level > 1:
                    base_parts = base_parts[: len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts)
                if node.module is None:  # from . import x: x is a module of the package
                    for alias in node.names:
                        yield node.lineno, f"{base}.{alias.name}"
                    continue
                target = f"{base}.{node.module}"
            else:
                target = node.module or ""
            if target == PACKAGE:
                for alias in node.names:
                    yield node.lineno, f"{PACKAGE}.{alias.name}"
            else:
                yield node.lineno, target
        elif isinstance(node, ast.Call) and node.args:
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            first = node.args[0]
            if (
                name in ("import_module", "__import__")
                and isinstance(first, ast.Constant)
                and isinstance(first.value, str)
                and not first.value.startswith(".")
            ):
                yield node.lineno, first.value


def violations(source: str, module: str, is_package: bool, where: str) -> list[str]:
    """Upward imports (and I/O imports in the core) of one module, one line each."""
    own = layer_of(module)
    if own is None:
        raise ValueError(f"{module} is not in the package")
    found: list[str] = []
    for line, target in imports_of(source, module, is_package):
        target_layer = layer_of(target)
        if target_layer is None:
            top = target.split(".")[0]
            if own in CORE and top in CORE_MAY_NOT_IMPORT:
                found.append(f"{where}:{line}: the core ({own}) imports {target}")
            continue
        allowed = MAY_IMPORT.get(own)
        if allowed is not None and target_layer not in allowed:
            found.append(
                f"{where}:{line}: {own or 'the package root'} imports {target}"
                f" (layer {target_layer or 'root'}, above or beside it)"
            )
    return found


def modules() -> list[Path]:
    return sorted(PACKAGE_DIR.rglob("*.py"))


# --------------------------------------------------------------------------- the tests


def test_no_upward_imports() -> None:
    found: list[str] = []
    for path in modules():
        module, is_package = module_name(path)
        where = str(path.relative_to(PACKAGE_DIR.parent))
        found += violations(path.read_text(encoding="utf-8"), module, is_package, where)
    assert found == [], "imports against the layer rule:\n" + "\n".join(found)


def test_every_layer_is_classified() -> None:
    layers = {layer_of(module_name(p)[0]) for p in modules()}
    unknown = sorted(str(x) for x in layers - set(MAY_IMPORT) - APPLICATION)
    assert unknown == [], f"put these layers in MAY_IMPORT or APPLICATION: {unknown}"
    missing = sorted(x for x in set(MAY_IMPORT) - {""} if x not in layers)
    assert missing == [], f"the rule table names layers that do not exist: {missing}"


def test_the_walker_finds_upward_imports() -> None:
    """A mutation check: upward imports written every way are caught, with their lines."""
    source = (
        "from __future__ import annotations\n"  # 1
        "import math\n"  # 2
        "from companion.types import GnssFix\n"  # 3  allowed
        "from companion.nav import frames\n"  # 4  allowed
        "def f():\n"  # 5
        "    from companion.engine import Engine\n"  # 6  upward, in a function
        "    return Engine\n"  # 7
        "if False:\n"  # 8
        "    import companion.pipeline as p\n"  # 9  upward, nested
        "from companion import sim\n"  # 10 upward, from the root
        "from ..integrity import monitor\n"  # 11 upward, relative
        "import importlib\n"  # 12
        "importlib.import_module('companion.mavlink.encode')\n"  # 13 upward, dynamic
        "import time\n"  # 14 the clock, in the core
    )
    found = violations(source, "companion.nav.fake", False, "fake.py")
    lines = [int(v.split(":")[1]) for v in found]
    assert lines == sorted([6, 9, 10, 11, 13, 14]), found
    assert any("companion.engine" in v for v in found)
    # the same imports are fine one layer up, except the ones still above it
    found_engine = violations(source, "companion.engine.fake", False, "fake.py")
    assert sorted(int(v.split(":")[1]) for v in found_engine) == [9, 10, 13, 14]
    # and the application layers may import anything
    assert violations(source, "companion.pipeline", False, "pipeline.py") == []


def test_relative_imports_resolve_against_the_package() -> None:
    src = "from . import kalman\nfrom .. import ins\nfrom ...engine import Engine\n"
    want = ["companion.nav.blend.kalman", "companion.nav.ins", "companion.engine"]
    assert [t for _, t in imports_of(src, "companion.nav.blend.core", False)] == want
    assert [t for _, t in imports_of(src, "companion.nav.blend", True)] == want
    assert violations(src, "companion.nav.blend.core", False, "core.py") == [
        "core.py:3: nav imports companion.engine (layer engine, above or beside it)"
    ]
