"""The README and the shipped parameters file stay in step with the code."""

from __future__ import annotations

from pathlib import Path
import re

from domplane_ros.config import (default_params_yaml, load_params_file, parameters_markdown,
                                 PlaneNodeConfig)

ROOT = Path(__file__).resolve().parents[1]


def test_readme_starts_with_the_two_commands():
    text = (ROOT / 'README.md').read_text(encoding='utf-8')
    block = re.search(r'```bash\n(.*?)```', text, re.S).group(1)
    commands = [line.split('#')[0].strip() for line in block.splitlines() if line.strip()]
    assert commands == ['make demo', 'make test']
    ci = (ROOT / '.ci' / 'run').read_text(encoding='utf-8')
    assert 'make test' in ci


def test_readme_parameter_table_is_current():
    text = (ROOT / 'README.md').read_text(encoding='utf-8')
    assert parameters_markdown().strip() in text


def test_params_file_holds_every_default():
    assert (ROOT / 'config' / 'plane_node.yaml').read_text(encoding='utf-8') == \
        default_params_yaml()
    assert load_params_file(str(ROOT / 'config' / 'plane_node.yaml')) == PlaneNodeConfig()


def test_readme_core_api_snippet_runs():
    text = (ROOT / 'README.md').read_text(encoding='utf-8')
    section = text.split('## Core API', 1)[1]
    code = re.search(r'```python\n(.*?)```', section, re.S).group(1)
    namespace: dict = {}
    exec(compile(code, 'README-core-api', 'exec'), namespace)  # noqa: S102
    est = namespace['est']
    assert est.ok
    assert namespace['candidates'].shape[1:] == (3, 3)
