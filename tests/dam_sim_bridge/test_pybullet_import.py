"""PyBullet's start-up banner stays out of our processes' output (no ROS)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / 'src'
PATHS = [str(SRC / 'dam_sim_bridge'), str(SRC / 'dam_common'), str(SRC / 'dam_hand_driver')]


def _run(code: str) -> subprocess.CompletedProcess[str]:
    script = f'import sys; sys.path[:0] = {PATHS!r}\n{code}'
    return subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                          timeout=120)


def test_a_plain_import_prints_the_banner_and_ours_does_not() -> None:
    # The reference: the extension module itself writes the banner to standard error.
    plain = _run('import pybullet')
    assert plain.returncode == 0, plain.stderr
    assert 'pybullet build time' in plain.stdout + plain.stderr
    ours = _run('from dam_sim_bridge.pybullet_import import pybullet, bullet_client\n'
                'print("connected", pybullet.connect(pybullet.DIRECT) >= 0)\n'
                'print("client", bullet_client.BulletClient.__name__)\n'
                'print("after", file=sys.stderr)')
    assert ours.returncode == 0, ours.stderr
    assert 'pybullet build time' not in ours.stdout + ours.stderr
    assert ours.stdout.split('\n')[:2] == ['connected True', 'client BulletClient']
    assert ours.stderr == 'after\n'  # standard error is back after the import


def test_the_world_module_imports_quietly() -> None:
    done = _run('import dam_sim_bridge.world; print("ok")')
    assert done.returncode == 0, done.stderr
    assert done.stdout == 'ok\n'
    assert 'pybullet build time' not in done.stderr
