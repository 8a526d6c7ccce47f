"""A configuration overlay too large or nested too deep is refused at once, with one line naming
the limit and the value (issue 34: a 3.4 MB overlay of 100,000 vertices took 112 s to be
refused, silently; a mapping nested 5,000 deep gave a 202 KB ``RecursionError`` traceback).

The time bound is relative: a refusal takes at most a small multiple of loading the shipped
configuration with a small overlay, both measured here on the same machine (best of three,
so that a moment of load on a shared machine decides nothing).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from dam_common.config import load_config
from dam_common.errors import ConfigError
from dam_common.polygon_section import MAX_VERTICES, ConvexPolygon
from dam_common.strict_yaml import MAX_YAML_BYTES, MAX_YAML_DEPTH

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG_FILE = REPO_ROOT / 'config' / 'dam.yaml'
#: How many times a normal load a refusal may take (the slowest, a flow list 5,000 deep, costs
#: about 7: PyYAML's scanner looks up to 1024 characters ahead for a key, over every open
#: bracket; the old refusal of 100,000 vertices took about 10,000).
MULTIPLE = 20.0


def _best_of_three(call: Callable[[], object]) -> float:
    """The shortest of three runs of ``call`` [s] (a ConfigError is what it is to raise)."""
    times = []
    for _ in range(3):
        start = time.perf_counter()
        try:
            call()
        except ConfigError:
            pass
        times.append(time.perf_counter() - start)
    return min(times)


@pytest.fixture(scope='module')
def normal_load_s(tmp_path_factory: pytest.TempPathFactory) -> float:
    small = tmp_path_factory.mktemp('small') / 'overlay.yaml'
    small.write_text('contact:\n  friction_angle_deg: 6.0\n', encoding='utf-8')
    return _best_of_three(lambda: load_config(CONFIG_FILE, [small]))


def _refusal(overlay: Path) -> tuple[str, float]:
    with pytest.raises(ConfigError) as info:
        load_config(CONFIG_FILE, [overlay])
    return str(info.value), _best_of_three(lambda: load_config(CONFIG_FILE, [overlay]))


def test_an_overlay_of_100000_vertices_is_refused_by_its_size_at_once(
        tmp_path: Path, normal_load_s: float) -> None:
    n = 100_000
    overlay = tmp_path / 'vertices.yaml'
    overlay.write_text('object:\n  library:\n    big:\n      shape: convex_polygon\n'
                       '      vertices_m:\n' + ''.join(
                           f'        - [{0.01 * math.cos(2 * math.pi * k / n):.9f}, '
                           f'{0.01 * math.sin(2 * math.pi * k / n):.9f}]\n' for k in range(n)),
                       encoding='utf-8')
    size = overlay.stat().st_size
    assert size > 3_000_000
    message, took = _refusal(overlay)
    assert message == (f'{str(overlay)!r} is {size / 1024 ** 2:.1f} MiB: a configuration file '
                       f'may have at most {MAX_YAML_BYTES // 1024} KiB (a configuration is '
                       'small)')
    assert took <= MULTIPLE * normal_load_s, (took, normal_load_s)


@pytest.mark.parametrize(('name', 'text'), [
    ('flow_mapping', 'a: ' + '{a: ' * 5000 + '1' + '}' * 5000 + '\n'),
    ('flow_list', 'a: ' + '[' * 5000 + ']' * 5000 + '\n'),
    ('block_mapping', 'a:\n' + ''.join(' ' * (k + 1) + 'k:\n' for k in range(200))
     + ' ' * 201 + 'v: 1\n'),
])
def test_a_mapping_nested_5000_deep_is_refused_by_its_depth_at_once(
        tmp_path: Path, normal_load_s: float, name: str, text: str) -> None:
    overlay = tmp_path / f'{name}.yaml'
    overlay.write_text(text, encoding='utf-8')
    message, took = _refusal(overlay)
    line = 33 if name == 'block_mapping' else 1
    assert message == (f'{str(overlay)!r} nests mappings and lists more than {MAX_YAML_DEPTH} '
                       f'levels deep (level {MAX_YAML_DEPTH + 1} on line {line}): a '
                       f'configuration may nest at most {MAX_YAML_DEPTH}')
    assert took <= MULTIPLE * normal_load_s, (took, normal_load_s)


def test_the_shipped_configuration_is_well_inside_the_limits() -> None:
    assert CONFIG_FILE.stat().st_size * 10 < MAX_YAML_BYTES
    load_config(CONFIG_FILE)


def test_a_polygon_of_too_many_vertices_is_refused_in_one_short_line() -> None:
    n = 100_000
    angles = [2 * math.pi * k / n for k in range(n)]
    vertices = [[math.cos(a), math.sin(a)] for a in angles]
    with pytest.raises(ValueError) as info:
        ConvexPolygon(vertices)
    assert str(info.value) == f'vertices: {n} vertices, at most {MAX_VERTICES}'
    # refused before the checks that loop over the vertices in Python: about as fast as one
    # polygon of the most vertices allowed is built
    most = [[math.cos(a), math.sin(a)] for a in angles[::n // MAX_VERTICES][:MAX_VERTICES]]
    refused = _best_of_three_s(lambda: _refused(vertices))
    assert refused <= MULTIPLE * _best_of_three_s(lambda: ConvexPolygon(most))


def _refused(vertices: list[list[float]]) -> None:
    with pytest.raises(ValueError):
        ConvexPolygon(vertices)


def _best_of_three_s(call: Callable[[], object]) -> float:
    times = []
    for _ in range(3):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return min(times)
