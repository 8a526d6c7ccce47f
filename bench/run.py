"""Run the benchmarks ``bench/bench_<name>.py`` and collect their reports.

Each module defines ``run(args) -> dict``; the dict is printed and written to
``bench/results/<name>.json``. Usage: ``python bench/run.py [name ...] [--quick] [--grid]``
(``--grid``: also the long grid measurement of ``bench_sweep``, about 15 minutes).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys
import time
from pathlib import Path

BENCH_DIR = Path(__file__).resolve().parent
REPO_ROOT = BENCH_DIR.parent
sys.path.insert(0, str(BENCH_DIR))
sys.path.insert(0, str(REPO_ROOT / 'tests'))  # ros_testing: start/stop processes by PID
for pkg in sorted((REPO_ROOT / 'src').iterdir()):
    if (pkg / 'setup.py').is_file():
        sys.path.insert(0, str(pkg))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('names', nargs='*', help='benchmarks to run (default: all)')
    parser.add_argument('--quick', action='store_true', help='fewer samples, for a smoke run')
    parser.add_argument('--grid', action='store_true',
                        help='sweep: also run the 480-trial grid with 1 and 2 workers (about '
                             '15 minutes; for a quiet machine)')
    args = parser.parse_args()
    available = {p.stem[len('bench_'):]: p for p in sorted(BENCH_DIR.glob('bench_*.py'))}
    names = args.names or list(available)
    unknown = [n for n in names if n not in available]
    if unknown:
        parser.error(f'unknown benchmark(s) {unknown}; available: {sorted(available)}')
    results_dir = BENCH_DIR / 'results'
    results_dir.mkdir(exist_ok=True)
    failed = False
    for name in names:
        spec = importlib.util.spec_from_file_location(f'bench_{name}', available[name])
        module = importlib.util.module_from_spec(spec)
        # registered by its name, so that worker processes (multiprocessing's spawn) find
        # the benchmark's functions by reference, as they import it from BENCH_DIR
        sys.modules[spec.name] = module
        assert spec.loader is not None
        spec.loader.exec_module(module)
        print(f'--- {name} ---', flush=True)
        started = time.monotonic()
        report = module.run(args)
        report['wall_time_s'] = round(time.monotonic() - started, 3)
        for key, value in report.items():
            print(f'{key:>40}: {value}')
        (results_dir / f'{name}.json').write_text(json.dumps(report, indent=2) + '\n')
        failed |= report.get('target_met') is False
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
