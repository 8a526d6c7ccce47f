"""The README and docs/ point only at what exists (issue 34 moved the README's reference material
to docs/): every relative Markdown link, every `docs/...` path, every `scripts/...` script and
every executable named by its install path `ros2_ws/install/<package>/lib/<package>/<name>`.

A path the repository's ``.gitignore`` names as generated (the results document's figures) may be
missing: a fresh clone has it only once the command the page gives has run."""

from __future__ import annotations

import ast
import re
import subprocess
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
PAGES = [REPO_ROOT / 'README.md', *sorted((REPO_ROOT / 'docs').glob('*.md'))]
LINK = re.compile(r'\]\(([^)\s]+)\)')
DOCS_PATH = re.compile(r'(?<![\w/.-])(docs/[\w./-]*[\w/])')
SCRIPT = re.compile(r'(?<![\w/.-])(scripts/[\w./-]+\.(?:sh|py))')
EXECUTABLE = re.compile(r'ros2_ws/install/(\w+)/lib/(\w+)/(\w+)')


def _console_scripts(package: str) -> set[str]:
    """The console scripts ``src/<package>/setup.py`` declares (none for a missing package)."""
    setup_py = REPO_ROOT / 'src' / package / 'setup.py'
    if not setup_py.is_file():
        return set()
    for node in ast.walk(ast.parse(setup_py.read_text(encoding='utf-8'))):
        if isinstance(node, ast.keyword) and node.arg == 'entry_points':
            entry_points = ast.literal_eval(node.value)
            return {spec.split('=')[0].strip()
                    for spec in entry_points.get('console_scripts', [])}
    return set()


def _present_or_generated(relative: str) -> bool:
    """Whether ``relative`` (to the repository, ``/``-ended for a directory) exists or is a
    generated path ``git`` ignores (missing from a fresh clone)."""
    if (REPO_ROOT / relative).exists():
        return True
    try:
        result = subprocess.run(['git', 'check-ignore', '-q', relative], cwd=REPO_ROOT,
                                check=False, capture_output=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return result.returncode == 0


def _name(page: Path) -> str:
    return str(page.relative_to(REPO_ROOT))


@pytest.mark.parametrize('page', PAGES, ids=_name)
def test_every_relative_link_reaches_a_file(page: Path) -> None:
    text = page.read_text(encoding='utf-8')
    broken = []
    for target in LINK.findall(text):
        if re.match(r'[a-z]+:', target) or target.startswith('#'):
            continue
        path = (page.parent / target.split('#', 1)[0]).resolve()
        relative = path.relative_to(REPO_ROOT).as_posix() if path.is_relative_to(
            REPO_ROOT) else str(path)
        if not _present_or_generated(relative + ('/' if target.endswith('/') else '')):
            broken.append(target)
    assert not broken, f'{_name(page)}: links to nothing: {broken}'


@pytest.mark.parametrize('page', PAGES, ids=_name)
def test_every_docs_path_and_script_named_exists(page: Path) -> None:
    text = page.read_text(encoding='utf-8')
    named = set(DOCS_PATH.findall(text)) | set(SCRIPT.findall(text))
    missing = sorted(p for p in named if not _present_or_generated(p))
    assert not missing, f'{_name(page)} names paths that do not exist: {missing}'


@pytest.mark.parametrize('page', PAGES, ids=_name)
def test_every_installed_executable_named_is_declared(page: Path) -> None:
    text = page.read_text(encoding='utf-8')
    unknown = sorted({f'{pkg}/{exe}' for pkg, lib_pkg, exe in EXECUTABLE.findall(text)
                      if pkg != lib_pkg or exe not in _console_scripts(pkg)})
    assert not unknown, f'{_name(page)} names executables no setup.py declares: {unknown}'


def test_the_readme_starts_with_a_quick_start() -> None:
    """A newcomer meets the quick start within the first lines, and the README stays short."""
    lines = (REPO_ROOT / 'README.md').read_text(encoding='utf-8').splitlines()
    headings = [i for i, line in enumerate(lines) if line.startswith('## ')]
    assert headings and lines[headings[0]] == '## Quick start', lines[headings[0]]
    assert headings[0] < 12, f'the quick start begins on line {headings[0] + 1}'
    assert len(lines) < 300, f'README.md has {len(lines)} lines'
