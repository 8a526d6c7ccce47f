"""scripts/bringup.sh and scripts/stop.sh as a user runs them: the suite comes up (with the
default object and with ``--object``), answers, and is stopped by PID; a name outside the
library is refused before anything starts."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest
from grasp_testing import config_with_free_ports

from ros_testing import RosClient

pytestmark = [pytest.mark.integration, pytest.mark.flaky(reruns=1)]

REPO_ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = REPO_ROOT / 'scripts'


def _env(tmp_path: Path) -> dict[str, str]:
    config = config_with_free_ports(tmp_path)
    return dict(os.environ, DAM_CONFIG=str(config), DAM_RUN_DIR=str(tmp_path / 'run'))


def _script(name: str, *args: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(['bash', str(SCRIPTS / name), *args], capture_output=True,
                          text=True, timeout=120, env=env, stdin=subprocess.DEVNULL)


@pytest.mark.parametrize('object_args', [(), ('--object', 'hex_bar')])
def test_bringup_serves_the_object_and_stop_stops_it(tmp_path: Path,
                                                     object_args: tuple[str, ...]) -> None:
    from dam_interfaces.srv import CheckLift

    env = _env(tmp_path)
    up = _script('bringup.sh', '--backend', 'sim', *object_args, env=env)
    try:
        assert up.returncode == 0, up.stdout + up.stderr
        client = RosClient()
        try:
            answer = client.call(CheckLift, '/check_lift', CheckLift.Request(), timeout=30.0)
        finally:
            client.close()
        assert answer.ok and answer.object == 'cylinder', answer.message
        run_dir = tmp_path / 'run'
        controller_log = (run_dir / 'spcm_controller.log').read_text(encoding='utf-8')
        expected = object_args[1] if object_args else 'cylinder'
        assert f'object {expected} (' in controller_log, controller_log
    finally:
        down = _script('stop.sh', env=env)
    assert down.returncode == 0, down.stdout + down.stderr
    assert 'stopped 3 process(es)' in down.stdout, down.stdout
    assert not list((tmp_path / 'run').glob('*.pid')), list((tmp_path / 'run').iterdir())


def test_run_sh_refuses_an_object_outside_the_library(tmp_path: Path) -> None:
    env = _env(tmp_path)
    refused = _script('run.sh', '--object', 'pencil', env=env)
    assert refused.returncode == 2, refused.stdout + refused.stderr
    assert "run.sh: --object: object 'pencil' is not in the object library" in refused.stderr
    assert not (tmp_path / 'run').exists() or not list((tmp_path / 'run').glob('*.pid'))
