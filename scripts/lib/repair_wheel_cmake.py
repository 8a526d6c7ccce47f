"""Repair the CMake exports of the ros-jazzy-* wheels installed under a prefix.

    python scripts/lib/repair_wheel_cmake.py PREFIX

The wheels' exported CMake files (PREFIX/share/*/cmake/*.cmake) name the wheel build machine's
Python and numpy include directories (/opt/python/cp3XX-cp3XX/...), and CMake refuses to
generate until they exist. This points them at the include directory of the Python running
this script and at the numpy it imports (run it with the interpreter, and PYTHONPATH, that the
build will use). Idempotent: a repaired file has nothing left to rewrite. Warns about any other
reference to the build machine left under PREFIX/share/*/cmake.
"""

from __future__ import annotations

import pathlib
import re
import sys
import sysconfig

BUILD_MACHINE = '/opt/python/'
NUMPY_RE = re.compile(
    r'/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+/site-packages/numpy/_core/include')
INCLUDE_RE = re.compile(r'/opt/python/cp3\d+-cp3\d+/include/python3\.\d+')


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(f'usage: {argv[0]} PREFIX', file=sys.stderr)
        return 2
    prefix = pathlib.Path(argv[1])
    try:
        import numpy
    except ImportError as exc:
        print(f'repair_wheel_cmake: numpy is not importable by {sys.executable} ({exc})',
              file=sys.stderr)
        return 1
    py_include = sysconfig.get_paths()['include']
    np_include = numpy.get_include()
    changed = 0
    left = []
    for path in sorted((prefix / 'share').glob('*/cmake/*.cmake')):
        text = path.read_text(encoding='utf-8', errors='surrogateescape')
        if BUILD_MACHINE not in text:
            continue
        new = INCLUDE_RE.sub(py_include, NUMPY_RE.sub(np_include, text))
        if new != text:
            path.write_text(new, encoding='utf-8', errors='surrogateescape')
            changed += 1
        if BUILD_MACHINE in new:
            left.append(path)
    files = 'file' if changed == 1 else 'files'
    print(f'    rewrote {changed} CMake {files} to {py_include} and {np_include}')
    if left:
        print('    warning: still naming the wheel build machine (' + BUILD_MACHINE + '...): '
              + ', '.join(str(p) for p in left), file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
