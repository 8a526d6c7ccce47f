"""A picture's file name decides its format, and one matplotlib cannot write is refused
(issue 34: ``lift_map --out x.jpgg`` wrote PNG data under that name)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dam_common.picture import picture_format, picture_formats

#: The first bytes of each format's file.
MAGIC = {'png': b'\x89PNG', 'jpg': b'\xff\xd8\xff', 'pdf': b'%PDF', 'svg': b'<?xml'}


def test_the_extension_names_the_format() -> None:
    assert picture_format('map.PNG') == 'png' and picture_format('a/b.pdf') == 'pdf'
    assert {'png', 'pdf', 'svg', 'jpg', 'jpeg'} <= set(picture_formats())
    assert 'pgf' not in picture_formats()  # needs LaTeX


@pytest.mark.parametrize('name', ['x.jpgg', 'x', 'x.pgf', 'x.csv'])
def test_a_name_matplotlib_cannot_write_is_refused_with_the_formats_it_can(name) -> None:
    with pytest.raises(ValueError) as info:
        picture_format(name)
    assert str(info.value).startswith(f'{name!r} has '), info.value
    assert '.png, ' in str(info.value) and '.svg' in str(info.value)


@pytest.mark.parametrize(('module', 'argv'), [
    ('dam_analysis.lift_map', ['--friction-angles', '5deg', '--out', '{dir}/x.jpgg']),
    ('dam_analysis.scale_map', ['--out', '{dir}/x.jpgg']),
    ('dam_analysis.csm_dependence', ['--out', '{dir}/x.jpgg']),
    ('dam_recorder.bag_cli', ['plot', '{dir}', '-o', '{dir}/x.jpgg']),
    ('dam_experiments.sweep_plot', ['{dir}', '-o', '{dir}/x.jpgg']),
])
def test_every_command_with_a_picture_refuses_it_before_any_work(
        module: str, argv: list[str], tmp_path: Path, capsys) -> None:
    import importlib

    main = importlib.import_module(module).main
    with pytest.raises(SystemExit) as info:
        main([a.format(dir=tmp_path) for a in argv])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "x.jpgg' has extension .jpgg: a picture is written as one of " in err, err
    assert not (tmp_path / 'x.jpgg').exists()


@pytest.mark.parametrize('suffix', ['jpg', 'pdf', 'svg', 'png'])
def test_lift_map_writes_the_format_its_extension_names(suffix: str, tmp_path: Path) -> None:
    from dam_analysis.lift_map import plot_map
    from dam_analysis.regions import Boundaries

    dp = np.linspace(0.0, math.radians(30.0), 5)
    boundaries = Boundaries(math.radians(5.0), dp, np.full(dp.size, 8.0), np.full(dp.size, 4.0))
    out = tmp_path / f'map.{suffix}'
    plot_map(out, [5.0], [boundaries], 20.0, 30.0)
    assert out.read_bytes().startswith(MAGIC[suffix]), out.read_bytes()[:8]
