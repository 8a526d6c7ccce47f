"""No two modules of the suite import each other.

A pair that does (often lazily, inside a function, which hides the cycle from the import
machinery but keeps it) means code sits in the wrong module: whatever both need belongs in a
third. The test reads every module under ``src/<package>/<package>/`` with :mod:`ast`, takes
every import in it (at the top, inside functions, under ``if TYPE_CHECKING:``, relative ones
resolved), maps each to the most specific module of the suite it names and fails, naming the
pair and the lines, when two modules import each other.

Left out: what a module runs as a script, under ``if __name__ == '__main__':`` at its top. It
never runs when the module is imported, so it makes no import between modules
(``python -m dam_sim_bridge.dynamixel_bus_program`` starts the program through its entry point
in ``dam_sim_bridge.entry_points``, which imports the program's module afresh).
"""

from __future__ import annotations

import ast
import itertools
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]


def project_modules(src: Path) -> dict[str, Path]:
    """Dotted name -> file of every module of the Python packages under ``src``.

    ``src/<package>/<package>/a/b.py`` is ``<package>.a.b``; an ``__init__.py`` is its
    package's module.
    """
    modules: dict[str, Path] = {}
    for package_dir in sorted(p for p in src.glob('*/*') if (p / '__init__.py').is_file()):
        if package_dir.name != package_dir.parent.name:  # src/<package>/<package> only
            continue
        for path in sorted(package_dir.rglob('*.py')):
            parts = path.relative_to(package_dir.parent).with_suffix('').parts
            if parts[-1] == '__init__':
                parts = parts[:-1]
            modules['.'.join(parts)] = path
    return modules


def _resolve(node: ast.ImportFrom, importer: str, is_package: bool) -> str:
    """The absolute module a ``from ... import`` names (relative levels resolved)."""
    if node.level == 0:
        return node.module or ''
    base = importer.split('.')
    if not is_package:
        base = base[:-1]  # a module's relative imports start at its package
    base = base[:len(base) - (node.level - 1)]
    return '.'.join(base + ([node.module] if node.module else []))


def _is_main_guard(statement: ast.stmt) -> bool:
    """Whether ``statement`` is ``if __name__ == '__main__':``."""
    test = statement.test if isinstance(statement, ast.If) else None
    return (isinstance(test, ast.Compare) and isinstance(test.left, ast.Name)
            and test.left.id == '__name__' and len(test.comparators) == 1
            and isinstance(test.comparators[0], ast.Constant)
            and test.comparators[0].value == '__main__')


def _known(name: str, modules: dict[str, Path]) -> str | None:
    """The longest prefix of the dotted ``name`` that is a module of the suite."""
    parts = name.split('.')
    for n in range(len(parts), 0, -1):
        candidate = '.'.join(parts[:n])
        if candidate in modules:
            return candidate
    return None


def imports_of(source: str, importer: str, modules: dict[str, Path],
               is_package: bool = False, filename: str = '<source>') -> dict[str, int]:
    """The suite's modules that ``source`` (module ``importer``) imports, with the first
    line of each import; every import statement anywhere in the module counts but those of
    its script part (``if __name__ == '__main__':`` at its top).

    ``from a.b import c`` imports module ``a.b.c`` when that is a module of the suite (a
    submodule), else ``a.b`` (a name in it). ``filename`` names the file in a syntax error.
    """
    tree = ast.parse(source, filename)
    tree.body = [s for statement in tree.body
                 for s in (statement.orelse if _is_main_guard(statement) else [statement])]
    found: dict[str, int] = {}
    for node in ast.walk(tree):
        targets: list[str | None] = []
        if isinstance(node, ast.Import):
            targets = [_known(alias.name, modules) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(node, importer, is_package)
            for alias in node.names:
                submodule = f'{base}.{alias.name}'
                targets.append(submodule if submodule in modules else _known(base, modules))
        for target in targets:
            if target is not None and target != importer:
                found[target] = min(found.get(target, node.lineno), node.lineno)
    return found


def import_graph(src: Path) -> tuple[dict[str, dict[str, int]], dict[str, Path]]:
    """Each module of the suite under ``src`` -> the suite's modules it imports (with a line),
    and the modules' files."""
    modules = project_modules(src)
    graph = {name: imports_of(path.read_text(encoding='utf-8'), name, modules,
                              path.name == '__init__.py', str(path.relative_to(src.parent)))
             for name, path in modules.items()}
    return graph, modules


def mutual_pairs(graph: dict[str, dict[str, int]]) -> list[tuple[str, str]]:
    """Pairs ``(a, b)``, ``a < b``, where ``a`` imports ``b`` and ``b`` imports ``a``."""
    return sorted((a, b) for a, b in itertools.combinations(sorted(graph), 2)
                  if b in graph[a] and a in graph[b])


def test_the_scan_sees_lazy_relative_and_type_checking_imports() -> None:
    """The scan finds what a cycle hides behind: an import inside a function, one under
    ``TYPE_CHECKING``, a relative one, and a submodule taken by ``from package import``; not
    the script part of a module."""
    modules = {name: Path() for name in ('pkg', 'pkg.a', 'pkg.b', 'pkg.c', 'pkg.d', 'pkg.e',
                                         'pkg.f')}
    source = '\n'.join([
        'from typing import TYPE_CHECKING',
        'import numpy',
        'if TYPE_CHECKING:',
        '    from pkg.b import Thing',
        'def f():',
        '    from .c import g',
        '    from pkg import d',
        '    import pkg.e.missing',
        '    return g',
        "if __name__ == '__main__':",
        '    from pkg.a import main',
        '    from pkg.f import run',
    ])
    assert imports_of(source, 'pkg.a', modules) == {'pkg.b': 4, 'pkg.c': 6, 'pkg.d': 7,
                                                     'pkg.e': 8}
    assert mutual_pairs({'pkg.a': {'pkg.b': 4}, 'pkg.b': {'pkg.a': 9},
                         'pkg.c': {'pkg.a': 1}}) == [('pkg.a', 'pkg.b')]


def test_no_two_modules_of_the_suite_import_each_other() -> None:
    graph, modules = import_graph(REPO_ROOT / 'src')
    # the scan reads the whole suite, lazy imports included (sweep runs a trial with
    # experiment's run_experiment, imported inside run_trial)
    assert len(modules) > 100, f'only {len(modules)} modules found under src/'
    assert 'dam_experiments.experiment' in graph['dam_experiments.sweep']
    pairs = mutual_pairs(graph)
    assert not pairs, 'modules that import each other: ' + '; '.join(
        f'{a} (line {graph[a][b]}) <-> {b} (line {graph[b][a]})' for a, b in pairs)
