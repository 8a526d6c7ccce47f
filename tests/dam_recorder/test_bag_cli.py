"""The ``bag`` command: its subcommands in-process and as the installed executable (what
``ros2 run dam_recorder bag`` starts), and its answers to bad input: one line on standard
error naming the path or the value, exit status 1 (2 for a malformed command line), never a
traceback."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import grasp_bags as gb
import pytest

from dam_recorder.bag_cli import build_parser, main

REPO_ROOT = Path(__file__).resolve().parents[2]
BAG_EXE = REPO_ROOT / 'ros2_ws' / 'install' / 'dam_recorder' / 'lib' / 'dam_recorder' / 'bag'


@pytest.fixture(scope='module')
def bags(tmp_path_factory, typestore, prefixes) -> dict[str, Path]:
    """A grasp bag, a directory of two episodes, and broken variants."""
    root = tmp_path_factory.mktemp('cli')
    grasp = gb.write_grasp_bag(root / 'grasp', typestore, prefixes, episode=gb.summary()).path
    episodes = root / 'episodes'
    gb.write_grasp_bag(episodes / '2026_11_29-18_05_12_success', typestore, prefixes,
                       topics=('/dam/status',), episode=gb.summary())
    gb.write_grasp_bag(episodes / '2026_11_29-18_06_40_failure', typestore, prefixes,
                       topics=('/dam/status',),
                       episode=gb.summary(outcome=3, outcome_name='FAILURE'))
    malformed = gb.write_grasp_bag(root / '2026_11_29-18_07_00_success', typestore, prefixes,
                                   topics=('/dam/status',),
                                   episode=gb.summary(k_theta='stiff')).path
    corrupt = root / 'corrupt'
    shutil.copytree(grasp, corrupt)
    (corrupt / 'metadata.yaml').write_text('rosbag2_bagfile_information:\n  version: [9\n')
    not_a_bag = root / 'not_a_bag'
    (not_a_bag / 'sub').mkdir(parents=True)
    (not_a_bag / 'notes.txt').write_text('x')
    return {'grasp': grasp, 'episodes': episodes, 'malformed': malformed, 'corrupt': corrupt,
            'not_a_bag': not_a_bag, 'missing': root / 'absent', 'root': root}


def run_exe(*args: str | os.PathLike[str], cwd: Path | None = None
            ) -> subprocess.CompletedProcess:
    if not BAG_EXE.is_file():
        pytest.fail(f'{BAG_EXE} is not installed (run scripts/setup.sh)')
    return subprocess.run([str(BAG_EXE), *map(str, args)], capture_output=True, text=True,
                          timeout=120, cwd=cwd)


def assert_one_line_error(done: subprocess.CompletedProcess, status: int, *words: str) -> None:
    assert done.returncode == status, done.stderr
    assert 'Traceback' not in done.stderr
    lines = done.stderr.strip().splitlines()
    if status == 1:
        assert len(lines) == 1, done.stderr
    for word in words:
        assert word in lines[-1], (word, done.stderr)


def test_help_of_every_subcommand(capsys) -> None:
    for argv, words in ((['--help'], ['info', 'plot', 'export', 'episode']),
                        (['info', '--help'], ['--json', 'largest gap', 'lost', 'outcome']),
                        (['plot', '--help'], ['--output', 'deg', 'N*m', 'phases', 'mm']),
                        (['export', '--help'], ['--topics', 'time_s', 'time_ns',
                                                'position.finger1_compliant_joint'])):
        with pytest.raises(SystemExit) as info:
            build_parser().parse_args(argv)
        assert info.value.code == 0
        text = ' '.join(capsys.readouterr().out.split())
        for word in words:
            assert word in text, (argv, word)


def test_in_process_subcommands(bags, tmp_path: Path, capsys) -> None:
    assert main(['info', str(bags['grasp'])]) == 0
    out = capsys.readouterr().out
    assert '/joint_states' in out and 'episode:    SUCCESS' in out
    assert main(['info', '--json', str(bags['episodes'])]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data['totals'] == {'SUCCESS': 1, 'FAILURE': 1}
    assert main(['plot', str(bags['grasp']), '-o', str(tmp_path / 'g.png')]) == 0
    assert (tmp_path / 'g.png').stat().st_size > 10_000
    # The rise printed: from the first pose to the last and to the highest (here the last).
    rise_mm = (gb.pose_z(gb.POSE_COUNT - 1) - gb.pose_z(0)) * 1e3
    assert f'at the end {rise_mm:.2f} mm, highest {rise_mm:.2f} mm' in capsys.readouterr().out
    assert main(['export', str(bags['grasp']), '-o', str(tmp_path / 'csv'), '--topics',
                 '/dam/status', '/sim/object_pose']) == 0
    assert sorted(p.name for p in (tmp_path / 'csv').iterdir()) == \
        ['dam-status.csv', 'sim-object_pose.csv']


def test_installed_info_of_a_bag_and_of_episodes(bags) -> None:
    done = run_exe('info', bags['grasp'])
    assert done.returncode == 0, done.stderr
    line = next(x for x in done.stdout.splitlines() if x.startswith('/dam/status '))
    assert line.split()[:4] == ['/dam/status', 'dam_interfaces/msg/DamStatus',
                                str(len(gb.PHASES)), '10.00']
    done = run_exe('info', '--json', bags['grasp'])
    data = json.loads(done.stdout)
    counts = {t['name']: t['count'] for t in data['topics']}
    assert counts['/sim/object_pose'] == gb.POSE_COUNT
    assert data['episode']['summary']['outcome_name'] == 'SUCCESS'
    done = run_exe('info', bags['episodes'])
    assert done.returncode == 0, done.stderr
    assert '2026_11_29-18_06_40_failure' in done.stdout
    assert done.stdout.strip().splitlines()[-2:] == ['  SUCCESS            1',
                                                     '  FAILURE            1']


def test_installed_plot_and_export(bags, tmp_path: Path) -> None:
    done = run_exe('plot', bags['grasp'], cwd=tmp_path)  # default: grasp.png here
    assert done.returncode == 0, done.stderr
    assert (tmp_path / 'grasp.png').read_bytes()[:4] == b'\x89PNG'
    assert 'grasp.png: grasp: SUCCESS' in done.stdout
    done = run_exe('export', bags['grasp'], '--topics', '/joint_states,/dam/status',
                   cwd=tmp_path)  # default: grasp_csv here
    assert done.returncode == 0, done.stderr
    with open(tmp_path / 'grasp_csv' / 'dam-status.csv', newline='') as stream:
        rows = list(csv.DictReader(stream))
    assert [r['phase'] for r in rows] == gb.PHASES
    assert sorted(p.name for p in (tmp_path / 'grasp_csv').iterdir()) == \
        ['dam-status.csv', 'joint_states.csv']


@pytest.mark.parametrize('case, argv, words', [
    ('missing', ['info', '{missing}'], ['{missing}', 'no such file or directory']),
    ('not a bag', ['info', '{not_a_bag}'], ['{not_a_bag}', 'not a bag']),
    ('not a bag, plot', ['plot', '{not_a_bag}'], ['{not_a_bag}', 'not a bag']),
    ('corrupt', ['info', '{corrupt}'], ['{corrupt}/metadata.yaml', 'not valid YAML']),
    ('corrupt, export', ['export', '{corrupt}', '-o', '{root}/out'],
     ['{corrupt}/metadata.yaml', 'not valid YAML']),
    ('malformed summary', ['info', '{malformed}'],
     ['{malformed}', "dam_episode.summary.k_theta: expected a list of numbers, got 'stiff'"]),
    ('malformed summary, plot', ['plot', '{malformed}', '-o', '{root}/m.png'],
     ['{malformed}', 'dam_episode.summary.k_theta']),
    ('unknown topic', ['export', '{grasp}', '-o', '{root}/out', '--topics', '/nope'],
     ['{grasp}', 'no topic /nope']),
    ('episodes to plot', ['plot', '{episodes}'], ['{episodes}', 'a directory of 2 bags']),
])
def test_installed_bad_input_is_one_line_and_status_1(bags, case, argv, words) -> None:
    values = {k: str(v) for k, v in bags.items()}
    done = run_exe(*[a.format(**values) for a in argv])
    assert_one_line_error(done, 1, *[w.format(**values) for w in words])
    assert done.stdout == ''


def test_an_episode_directory_with_a_bad_episode_prints_the_table_and_fails(bags) -> None:
    root = bags['root'] / 'mixed'
    shutil.copytree(bags['episodes'], root)
    shutil.copytree(bags['malformed'], root / bags['malformed'].name)
    done = run_exe('info', root)
    assert done.returncode == 1
    assert 'Traceback' not in done.stderr
    assert done.stderr.strip() == (
        f'bag info: {root / bags["malformed"].name}: dam_episode.summary.k_theta: expected a '
        "list of numbers, got 'stiff'")
    assert '2026_11_29-18_07_00_success' in done.stdout and 'ERROR' in done.stdout


@pytest.mark.parametrize('argv, words', [
    ([], ['required']),
    (['show', 'x'], ["invalid choice: 'show'"]),
    (['info'], ['BAG']),
    (['export', 'x', '--topics', 'joint_states'], ["'joint_states' is not a topic name"]),
    (['plot', 'x', '--dpi', 'high'], ["invalid int value: 'high'"]),
])
def test_installed_usage_errors_exit_2(argv, words) -> None:
    done = run_exe(*argv)
    assert_one_line_error(done, 2, *words)
    assert done.stderr.startswith('usage: bag')



def test_plot_and_export_say_on_stderr_what_they_do_while_they_work(bags, tmp_path) -> None:
    """A line every DAM_PROGRESS_S seconds (5 by default; here 0.01, so that a small bag is
    slow enough), on stderr only: standard output is what it was."""
    env = {**os.environ, 'DAM_PROGRESS_S': '0.01'}
    picture = tmp_path / 'grasp.png'
    for argv, first in ((('plot', bags['grasp'], '-o', picture), f'{picture}: '),
                        (('export', bags['grasp'], '-o', tmp_path / 'csv'), str(tmp_path))):
        done = subprocess.run([str(BAG_EXE), *map(str, argv)], capture_output=True, text=True,
                              timeout=120, env=env)
        assert done.returncode == 0, done.stderr
        assert done.stdout.startswith(first)
        assert 'bag ' + argv[0] not in done.stdout
        lines = [ln for ln in done.stderr.splitlines() if ln.startswith(f'bag {argv[0]}: ')]
        assert lines and all(re.search(r', \d+ s$', ln) for ln in lines), done.stderr


def test_reading_a_bag_counts_its_messages_in_the_progress_line(bags) -> None:
    from dam_common.progress import Progress
    from dam_recorder.bag_reading import BagReader

    lines = []
    with Progress('bag export', 'writing CSV', period=0.0) as progress, \
            BagReader(bags['grasp']) as reader:
        n = 0
        for n, _message in enumerate(reader.raw_messages(['/joint_states']), start=1):
            if n == 10:
                lines.append(progress.line())
        lines.append(progress.line())
    assert n > 10
    assert re.match(rf'bag export: reading messages of grasp 10 of {n:,} \(\d+ %\), \d+ s$',
                    lines[0]), lines
    assert re.match(rf'bag export: writing CSV \(read {n:,} messages\), \d+ s$', lines[1])
