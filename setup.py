"""Packaging for cloth_mg_ros (ament_python: `colcon build` and `pip install` both work)."""

import os
from glob import glob

from setuptools import find_packages, setup

package_name = 'cloth_mg_ros'
here = os.path.dirname(os.path.abspath(__file__))


def share_tree(src):
    """data_files entries installing every file under `src` into share/<package>/<src>.

    Sub-folders keep their names (a rosbag2 bag is a folder holding metadata.yaml and an
    .mcap file). Hidden files are skipped; a missing or empty folder yields nothing.
    """
    groups = {}
    for path in sorted(glob(os.path.join(src, '**', '*'), root_dir=here, recursive=True)):
        if not os.path.isfile(os.path.join(here, path)):
            continue
        target = os.path.normpath(
            os.path.join('share', package_name, os.path.dirname(path)))
        groups.setdefault(target, []).append(path)
    return sorted(groups.items())


setup(
    name=package_name,
    version='0.6.0',
    packages=find_packages(exclude=['test', 'test.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'LICENSE']),
        *share_tree('config'),
        *share_tree('bags'),
        *share_tree('launch'),
        *share_tree('rviz'),
    ],
    python_requires='>=3.10',
    install_requires=[
        'numpy',
        'scipy',
        'numba',
        'trimesh',
        'rosbags',
        'pyyaml',
        'tqdm',
        # CHOLMOD: the exact solves tolerance auto calibrates against, and the 'direct' solver.
        'cvxopt',
    ],
    # What the node and the headless runs need is above; `make demo` and `make test` install
    # every extra. cloth-mg names the extra a command needs when it is missing
    # (cloth_mg_ros.extras).
    extras_require={
        # benchmarks: charts and pictures (matplotlib; bench pareto rasterises the garment's
        # outline with pillow), the 'amg' baseline (pyamg), one BLAS thread in the timed
        # comparisons (threadpoolctl), and the sweeps' Dask cluster.
        'bench': ['matplotlib', 'pillow', 'pyamg', 'threadpoolctl', 'distributed'],
        # `cloth-mg batch` and the benchmark sweeps run their tasks on Dask distributed.
        'cluster': ['distributed'],
        # The test suite builds the docs too (test/test_docs.py), so it takes the docs' pins;
        # pytest-xdist runs it on two workers (Makefile).
        'test': ['pytest', 'pytest-xdist', 'ruff', 'colcon-common-extensions',
                 'sphinx~=9.0', 'myst-parser~=5.2'],
        # `make docs`: the Sphinx site in doc/ (MyST markdown pages).
        'docs': ['sphinx~=9.0', 'myst-parser~=5.2'],
        # `cloth-mg bench peers`: Newton (SolverStyle3D, SolverVBD on the Warp CPU device) and
        # MuJoCo flex. Newton's cloth solvers need only warp-lang (not newton[sim], which pins
        # an older mujoco for SolverMuJoCo); MuJoCo 4's discrete integrator steps stiff flexes.
        'peers': ['newton~=1.8.0', 'warp-lang~=1.19.0', 'mujoco~=4.0.0'],
    },
    zip_safe=True,
    maintainer='cloth_mg_ros maintainers',
    maintainer_email='maintainers@cloth-mg-ros.org',
    description='ROS 2 cloth simulator: implicit integration with a physically faithful '
                'multigrid solver, publishing RViz markers.',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'cloth-mg = cloth_mg_ros.cli.main:main',
            'cloth_node = cloth_mg_ros.ros.node:main',
            'cloth_node_managed = cloth_mg_ros.ros.node:main_managed',
        ],
    },
)
