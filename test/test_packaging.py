"""Packaging checks: package.xml is valid for colcon, and `colcon build` installs the package
the ament_python way (scripts in lib/<package>, package.xml and the ament index under share/)."""

import ast
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
PACKAGE = 'cloth_mg_ros'
EXEC_DEPENDS = {
    'rclpy', 'std_msgs', 'geometry_msgs', 'visualization_msgs', 'diagnostic_msgs',
    'std_srvs', 'python3-numpy', 'python3-scipy',
}
EMAIL = re.compile(r'^[A-Za-z0-9._%+-]+@[A-Za-z0-9-]+(\.[A-Za-z0-9-]+)*\.[A-Za-z]{2,}$')
# What a ROS workspace needs from the checkout (the tracked-type files, no venv or build output).
WORKSPACE_ITEMS = ['package.xml', 'setup.py', 'setup.cfg', 'LICENSE', 'resource', PACKAGE,
                   'config', 'bags', 'launch', 'rviz', 'rosdep']
# The rosdep key of each top-level module the package (or its launch file) imports; None: the
# standard library, the package itself, or an optional extra (`pip install .[peers]`).
MODULE_KEYS = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'numba': 'python3-numba',
    'yaml': 'python3-yaml', 'matplotlib': 'python3-matplotlib', 'PIL': 'python3-pil',
    'mpl_toolkits':
    'python3-matplotlib', 'tqdm': 'python3-tqdm', 'trimesh': 'python3-trimesh-pip',
    'rosbags': 'python3-rosbags-pip', 'pyamg': 'python3-pyamg-pip',
    'cvxopt': 'python3-cvxopt-pip', 'distributed': 'python3-distributed-pip',
    'threadpoolctl': 'python3-threadpoolctl-pip',
    'rclpy': 'rclpy', 'rcl_interfaces': 'rcl_interfaces',
    'ament_index_python': 'ament_index_python', 'std_msgs': 'std_msgs',
    'std_srvs': 'std_srvs', 'geometry_msgs': 'geometry_msgs', 'sensor_msgs': 'sensor_msgs',
    'shape_msgs': 'shape_msgs', 'visualization_msgs': 'visualization_msgs',
    'diagnostic_msgs': 'diagnostic_msgs', 'rosgraph_msgs': 'rosgraph_msgs',
    'lifecycle_msgs': 'lifecycle_msgs',
    'launch': 'launch', 'launch_ros': 'launch_ros',
    'cloth_mg_ros': None, 'newton': None, 'warp': None, 'mujoco': None,
}
# Keys rosdistro's rosdep/python.yaml defines (the rest must be in rosdep/cloth_mg_ros.yaml).
ROSDISTRO_PYTHON_KEYS = {
    'python3-numpy', 'python3-scipy', 'python3-numba', 'python3-yaml', 'python3-matplotlib',
    'python3-tqdm', 'python3-trimesh-pip', 'python3-pytest', 'python3-pil',
}


def test_package_xml_is_format3_with_dependencies_and_valid_maintainer():
    root = ET.parse(REPO / 'package.xml').getroot()
    assert root.tag == 'package'
    assert root.get('format') == '3'
    assert root.findtext('name') == PACKAGE
    assert re.fullmatch(r'\d+\.\d+\.\d+', root.findtext('version'))
    assert root.findtext('license')
    exec_depends = {e.text.strip() for e in root.findall('exec_depend')}
    assert EXEC_DEPENDS <= exec_depends, EXEC_DEPENDS - exec_depends
    assert 'rviz2' in exec_depends  # the launch file starts it with rviz:=true
    assert 'python3-pytest' in {e.text.strip() for e in root.findall('test_depend')}
    maintainers = root.findall('maintainer')
    assert maintainers
    for maintainer in maintainers:
        # colcon silently ignores a package whose maintainer e-mail is not valid
        assert EMAIL.match(maintainer.get('email', '')), maintainer.get('email')
    assert root.findtext('export/build_type') == 'ament_python'


def _imported_modules() -> set[str]:
    """Top-level names of every module imported anywhere in the package and the launch
    files (module level or inside functions)."""
    names = set()
    for path in [*(REPO / PACKAGE).rglob('*.py'), *(REPO / 'launch').glob('*.py')]:
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                names.update(a.name.split('.')[0] for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split('.')[0])
    return names - set(sys.stdlib_module_names) - {'__future__'}


def test_every_import_has_a_rosdep_key_and_every_key_resolves():
    root = ET.parse(REPO / 'package.xml').getroot()
    depends = {e.text.strip() for e in root.iter() if e.tag.endswith('depend') and e.text}
    modules = _imported_modules()
    unknown = modules - set(MODULE_KEYS)
    assert not unknown, f'imports without a rosdep key in MODULE_KEYS: {sorted(unknown)}'
    missing = {MODULE_KEYS[m] for m in modules if MODULE_KEYS[m]} - depends
    assert not missing, f'package.xml lacks {sorted(missing)}'
    # Python keys rosdistro does not define come with the package's own rosdep source.
    local = yaml.safe_load((REPO / 'rosdep' / f'{PACKAGE}.yaml').read_text())
    python_keys = {d for d in depends if d.startswith('python3-')}
    undefined = python_keys - ROSDISTRO_PYTHON_KEYS - set(local)
    assert not undefined, f'keys neither in rosdistro nor in rosdep/: {sorted(undefined)}'
    for key, rule in local.items():
        for platform in ('debian', 'ubuntu'):
            assert rule[platform]['pip']['packages'], (key, platform)


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
    assert (share / PACKAGE / 'LICENSE').is_file()
    # config/, bags/, launch/ and rviz/ are installed with their sub-folders (bags are
    # folders): `ros2 launch cloth_mg_ros cloth.launch.py` finds the launch file there.
    assert (share / PACKAGE / 'launch' / 'cloth.launch.py').is_file()
    assert (share / PACKAGE / 'rviz' / 'cloth.rviz').is_file()
    for folder in ('config', 'bags', 'launch', 'rviz'):
        for src in (REPO / folder).rglob('*'):
            rel = src.relative_to(REPO)
            if src.is_file() and not any(p.startswith('.') for p in rel.parts):
                assert (share / PACKAGE / rel).is_file(), rel
