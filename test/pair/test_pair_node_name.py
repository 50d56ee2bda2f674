"""plane_pair --node-name reads the parameters file's blocks of a renamed node (audit)."""

from __future__ import annotations

from domplane_ros.pair import cli
import pytest


@pytest.fixture
def front_params(tmp_path):
    path = tmp_path / 'front.yaml'   # a file for '-r __node:=front_plane'
    path.write_text('front_plane:\n  ros__parameters:\n    prior:\n'
                    '      tilt_deg: [-5.0, 5.0]\n')
    return path


def test_configure_reads_the_named_nodes_block(front_params):
    assert cli.configure(str(front_params), node_name='front_plane').prior.tilt_deg == (
        -5.0, 5.0)


def test_a_file_for_a_renamed_node_is_refused_naming_the_option(front_params, capsys,
                                                                tmp_path):
    image = tmp_path / 'missing.png'
    rc = cli.main([str(image), str(image), '--params-file', str(front_params)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == cli.EXIT_REFUSED and len(err) == 1
    assert 'blocks found: front_plane' in err[0] and '--node-name NAME' in err[0]
    assert '--node-name' in (cli.build_parser().format_help())
