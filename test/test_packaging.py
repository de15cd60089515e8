"""Packaging checks: package.xml is valid for colcon, and `colcon build` installs the package
the ament_python way (scripts in lib/<package>, package.xml and the ament index under share/)."""

import importlib.util
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = 'cloth_mg_ros'
EXEC_DEPENDS = {
    'rclpy', 'std_msgs', 'geometry_msgs', 'visualization_msgs', 'diagnostic_msgs',
    'std_srvs', 'python3-numpy', 'python3-scipy',
}
EMAIL = re.compile(r'^[A-Za-z0-9._%+-]+@[A-Za-z0-9-]+(\.[A-Za-z0-9-]+)*\.[A-Za-z]{2,}$')
# What a ROS workspace needs from the checkout (the tracked-type files, no venv or build output).
WORKSPACE_ITEMS = ['package.xml', 'setup.py', 'setup.cfg', 'resource', PACKAGE, 'config', 'bags']


def test_package_xml_is_format3_with_dependencies_and_valid_maintainer():
    root = ET.parse(REPO / 'package.xml').getroot()
    assert root.tag == 'package'
    assert root.get('format') == '3'
    assert root.findtext('name') == PACKAGE
    assert re.fullmatch(r'\d+\.\d+\.\d+', root.findtext('version'))
    assert root.findtext('license')
    exec_depends = {e.text.strip() for e in root.findall('exec_depend')}
    assert EXEC_DEPENDS <= exec_depends, EXEC_DEPENDS - exec_depends
    assert 'python3-pytest' in {e.text.strip() for e in root.findall('test_depend')}
    maintainers = root.findall('maintainer')
    assert maintainers
    for maintainer in maintainers:
        # colcon silently ignores a package whose maintainer e-mail is not valid
        assert EMAIL.match(maintainer.get('email', '')), maintainer.get('email')
    assert root.findtext('export/build_type') == 'ament_python'


def test_ament_marker_and_setup_cfg_follow_ament_python_layout():
    assert (REPO / 'resource' / PACKAGE).is_file()
    cfg = (REPO / 'setup.cfg').read_text()
    assert f'script_dir=$base/lib/{PACKAGE}' in cfg
    assert f'install_scripts=$base/lib/{PACKAGE}' in cfg


def _colcon_command():
    if importlib.util.find_spec('colcon_core') is None:
        return None
    exe = Path(sys.executable).parent / 'colcon'
    if exe.is_file():
        return [str(exe)]
    # colcon_core has no __main__: call its entry point function
    return [sys.executable, '-c',
            'import sys; from colcon_core.command import main; sys.exit(main())']


@pytest.mark.skipif(_colcon_command() is None,
                    reason='colcon is not importable (pip install colcon-common-extensions)')
def test_colcon_build_installs_ament_python_layout(tmp_path):
    ws = tmp_path / 'ws'
    pkg = ws / 'src' / PACKAGE
    pkg.mkdir(parents=True)
    ignore = shutil.ignore_patterns('__pycache__', '*.pyc', '*.egg-info')
    for item in WORKSPACE_ITEMS:
        src = REPO / item
        if src.is_dir():
            shutil.copytree(src, pkg / item, ignore=ignore)
        elif src.is_file():
            shutil.copy2(src, pkg / item)

    env = dict(os.environ, COLCON_HOME=str(tmp_path / 'colcon_home'))
    cmd = _colcon_command() + ['build', '--base-paths', 'src',
                               '--event-handlers', 'console_direct+']
    proc = subprocess.run(cmd, cwd=ws, env=env, capture_output=True, text=True, timeout=240,
                          check=False)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]

    prefix = ws / 'install' / PACKAGE
    assert (prefix / 'lib' / PACKAGE / 'cloth_node').is_file(), proc.stdout[-4000:]
    assert (prefix / 'lib' / PACKAGE / 'cloth-mg').is_file(), proc.stdout[-4000:]
    share = prefix / 'share'
    assert (share / PACKAGE / 'package.xml').is_file()
    assert (share / 'ament_index' / 'resource_index' / 'packages' / PACKAGE).is_file()
    # config/ and bags/ are installed with their sub-folders (bags are folders).
    for folder in ('config', 'bags'):
        for src in (REPO / folder).rglob('*'):
            rel = src.relative_to(REPO)
            if src.is_file() and not any(p.startswith('.') for p in rel.parts):
                assert (share / PACKAGE / rel).is_file(), rel
