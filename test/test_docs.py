"""The README, the docs and the shipped parameters file stay in step with the code."""

from __future__ import annotations

from pathlib import Path
import re

from domplane_ros.config import default_params_yaml, parameters_markdown, PlaneNodeConfig
from domplane_ros.params_file import load_params_file

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'
DOCS = ROOT / 'docs'
# The user's how-to must be within this many lines of the README's top.
HOW_TO_LINES = 120


def _readme() -> str:
    return README.read_text(encoding='utf-8')


def test_readme_starts_with_the_two_commands():
    block = re.search(r'```bash\n(.*?)```', _readme(), re.S).group(1)
    commands = [line.split('#')[0].strip() for line in block.splitlines() if line.strip()]
    assert commands == ['make demo', 'make test']
    ci = (ROOT / '.ci' / 'run').read_text(encoding='utf-8')
    assert [line for line in ci.splitlines()
            if line.strip() and not line.startswith(('#', 'set ', 'cd '))] == ['make test']


def test_how_to_for_a_rig_is_in_the_first_lines():
    lines = _readme().splitlines()
    start = lines.index('## Use it on your rig')
    end = next(k for k in range(start + 1, len(lines)) if lines[k].startswith('## '))
    assert start < 30 and end <= HOW_TO_LINES, (start, end)
    how_to = '\n'.join(lines[start:end])
    first = next(line for line in lines[start + 1:] if line.strip())
    assert first.startswith('**1. Try two images.** `plane_pair`'), first
    for words in ('f = (W/2) / tan(HFOV/2)', 'prior.focal_px', 'prior.baseline_over_height',
                  'prior.tilt_deg', 'prior.vergence_deg', 'Which camera is left',
                  'plane_replay', '--csv', 'wrong prior', 'plane/debug_image', 'Foxglove',
                  'rqt_image_view', 'mcap'):
        assert words in how_to, words
    assert sum(line.startswith('![') for line in lines[:start]) == 1   # one picture


def test_docs_hold_the_method_the_parameters_and_the_figures():
    text = _readme()
    for name in ('METHOD.md', 'PARAMETERS.md', 'BENCHMARKS.md', 'ARCHITECTURE.md'):
        assert f'docs/{name}' in text, name
        assert (DOCS / name).is_file(), name
    for path in [README] + sorted(DOCS.glob('*.md')):
        doc = path.read_text(encoding='utf-8')
        for target in re.findall(r'\]\(([^)#:]+)(?:#[^)]*)?\)', doc):
            assert (path.parent / target).exists(), f'{path.name}: link to {target}'
    benchmarks = (DOCS / 'BENCHMARKS.md').read_text(encoding='utf-8')
    assert re.search(r'20\d\d-\d\d-\d\d', benchmarks) and 'Xeon' in benchmarks


def test_parameter_table_is_current():
    assert parameters_markdown().strip() in (DOCS / 'PARAMETERS.md').read_text(encoding='utf-8')
    assert '| parameter | default | range | description |' not in _readme()


def test_params_file_holds_every_default():
    assert (ROOT / 'config' / 'plane_node.yaml').read_text(encoding='utf-8') == \
        default_params_yaml()
    assert load_params_file(str(ROOT / 'config' / 'plane_node.yaml')) == PlaneNodeConfig()


def test_readme_core_api_snippet_runs():
    section = _readme().split('## Core API', 1)[1]
    code = re.search(r'```python\n(.*?)```', section, re.S).group(1)
    namespace: dict = {}
    exec(compile(code, 'README-core-api', 'exec'), namespace)  # noqa: S102
    est = namespace['est']
    assert est.ok
    assert namespace['candidates'].shape[1:] == (3, 3)
